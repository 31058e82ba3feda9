"""The level-specific candidate lumbosacral_disc_height (lumbar.experiments.effects): its sourced range read from the
morphometry table, the scaled disc (analytic scaling, exact Jacobian against finite differences in both evaluation
paths), the identity at zero and at any other level, and its report on the real rows (lumbar.discovery.real_data)."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lumbar.discovery import real_data as RD
from lumbar.experiments import effects as fx
from lumbar.mechanics import kernel
from lumbar.mechanics.elements.disc import disc_axial_force, disc_torque

from test_model import fd_jacobian, perturbed_state

ROOT = Path(__file__).resolve().parents[1]
TABLE = ROOT / "data" / fx.LUMBOSACRAL_DISC_TABLE
YAMAMOTO = ROOT / "data" / "experiments" / "yamamoto1989_levels_original_text.csv"
NAME = "lumbosacral_disc_height"


def config():
    return {"seed": 7, "characteristics": {"data_dir": str(ROOT / "data" / "characteristics")},
            "geometry": {"kind": "visible_human", "path": str(ROOT / "data" / "geometry" / "visible_human_lss")},
            "discovery": {"grid_points": 5, "null_specimens": 0, "n_bootstrap": 199}}


@pytest.fixture(scope="module")
def units():
    return RD.level_units(config(), ["L4-L5", "L5-S1"])


SCEN = pd.DataFrame({"stage": "intact", "direction": ["flexion", "extension", "axial_rotation_left"],
                     "moment_nm": 10.0})


# ------------------------------------------------------------------ the sourced range
def test_sourced_range_is_the_spread_of_the_sources_height_ratios():
    t = pd.read_csv(TABLE)
    t = t[t["quantity"] == "disc_height_middle"]
    ratios = [g.set_index("level")["value"]["L5-S1"] / g.set_index("level")["value"]["L4-L5"]
              for _, g in t.groupby("source")]
    lo, hi, src = fx.sourced_range(NAME)
    assert len(ratios) >= 2 and lo == pytest.approx(min(ratios) - 1) and hi == pytest.approx(max(ratios) - 1)
    assert lo < 0 < hi and fx.LUMBOSACRAL_DISC_TABLE in src
    # independence: no source of the range is the abstract whose ROM rows the candidate is judged on
    assert not t["source"].str.contains("Yamamoto").any()
    assert set(t["kind"]) == {"original_text"}
    # control: a candidate without a sourced range has none
    assert fx.sourced_range("ligament_prestrain") is None


def test_sourced_range_refuses_a_table_without_both_levels_or_in_other_units(tmp_path):
    t = pd.read_csv(TABLE)
    one = tmp_path / "one.csv"
    t[t["level"] == "L4-L5"].to_csv(one, index=False)
    with pytest.raises(ValueError, match=r"one\.csv: no source gives disc_height_middle at both L4-L5 and L5-S1"):
        fx.lumbosacral_disc_height_range(one)
    cm = tmp_path / "cm.csv"
    t.assign(unit="cm").to_csv(cm, index=False)
    with pytest.raises(ValueError, match=r"cm\.csv, column 'unit'.*expected mm"):
        fx.lumbosacral_disc_height_range(cm)
    with pytest.raises(ValueError, match="not found"):
        fx.lumbosacral_disc_height_range(tmp_path / "missing.csv")


# ------------------------------------------------------------------ the scaled disc
def test_disc_model_is_the_disc_law_per_unit_height(units):
    """A disc 1 + d times as tall of the same material: every law takes its argument divided by 1 + d, so under the
    same torque the disc alone rotates 1 + d times as far (the nonlinear Eq. 3 included)."""
    u = units["L5-S1"]
    d = 0.25
    before = {k: tuple(v) for k, v in u.model.discs[0].torque.items()}
    m0, m1 = u.model, u.disc_model(d)
    assert {k: tuple(v) for k, v in m0.discs[0].torque.items()} == before          # the unit's own model untouched
    assert m1 is not m0 and u.disc_model(d) is m1                       # one copy per value
    phi = np.random.default_rng(3).normal(0, 0.05, (20, 3))
    for a, b in zip(m0.discs, m1.discs):
        np.testing.assert_allclose(disc_torque(phi, b.torque)[0], disc_torque(phi / (1 + d), a.torque)[0],
                                   rtol=1e-12, atol=1e-12)
        # control: the amplitude scaling T / (1 + d) is another law (Eq. 3 is not linear)
        assert np.abs(disc_torque(phi, b.torque)[0] - disc_torque(phi, a.torque)[0] / (1 + d)).max() > 1e-3
        rz = -np.linspace(1e-5, 1e-3, 7)                                 # compression
        np.testing.assert_allclose(disc_axial_force(rz, b.k_quadratic, b.k_linear)[0],
                                   disc_axial_force(rz / (1 + d), a.k_quadratic, a.k_linear)[0], rtol=1e-12)
        assert b.k_shear == pytest.approx(a.k_shear / (1 + d))
    # controls: at zero, and at another level, the unit's own model (the same object)
    assert u.disc_model(0.0) is m0
    assert units["L4-L5"].disc_model(d) is units["L4-L5"].model
    with pytest.raises(ValueError, match="outside its bounds"):
        u.disc_model(-1.0)


@pytest.mark.skipif(not kernel.HAVE_NUMBA, reason="numba not installed (pinned in environment.txt)")
@pytest.mark.parametrize("mode", ["compiled", "reference"])
def test_scaled_disc_jacobian_matches_finite_differences(units, mode):
    m = units["L5-S1"].disc_model(0.6)
    x, R, loads = perturbed_state(m, 2, 11)
    with kernel.use(mode):
        Q1, J = m.evaluate(x, R, loads)
        Jfd = fd_jacobian(m, x, R, loads)
        Q0, _ = units["L5-S1"].model.evaluate(x, R, loads)
    assert np.abs(J - Jfd).max() < 1e-8 * np.abs(J).max() + 1e-4
    assert np.abs(Q1 - Q0).max() > 1e-3                    # control: the scaled disc changes the residual


# ------------------------------------------------------------------ solved variants
def test_zero_is_bitwise_the_model_and_the_rom_grows_with_the_height(units):
    u = units["L5-S1"]
    base = u.simulate(SCEN, {})[0]
    d = np.array([0.0, -0.07, 0.045, 0.3])
    rom = u.simulate(SCEN, {NAME: d})[0]
    np.testing.assert_array_equal(rom[0], base[0])
    # a taller (softer) disc moves more in flexion and axial rotation, a shorter one less (sign control)
    assert rom[3, 0] > rom[2, 0] > rom[0, 0] > rom[1, 0]
    assert rom[3, 2] > rom[0, 2] > rom[1, 2]
    # wrong-level control: at L4-L5 the candidate changes nothing, bit for bit
    b45 = units["L4-L5"].simulate(SCEN, {})[0]
    np.testing.assert_array_equal(units["L4-L5"].simulate(SCEN, {NAME: np.array([0.3])})[0][0], b45[0])


def test_variants_keep_their_order_beside_another_effect(units):
    u = units["L5-S1"]
    both = u.simulate(SCEN, {NAME: np.array([0.3, 0.0, 0.3]), "ligament_prestrain": np.array([0.0, 0.02, 0.02])})[0]
    a = u.simulate(SCEN, {NAME: np.array([0.3]), "ligament_prestrain": np.array([0.0])})[0][0]
    b = u.simulate(SCEN, {"ligament_prestrain": np.array([0.02])})[0][0]
    c = u.simulate(SCEN, {NAME: np.array([0.3]), "ligament_prestrain": np.array([0.02])})[0][0]
    np.testing.assert_allclose(both, np.stack([a, b, c]), atol=1e-9)
    assert np.abs(a - c).max() > 1e-3                      # control: the rows differ, so an order mix-up would fail


def test_masks_params_refuses_the_height_it_cannot_express(units):
    with pytest.raises(ValueError, match="changes the model, not the masks"):
        units["L5-S1"].masks_params(["intact"], {NAME: np.array([0.2])})
    units["L4-L5"].masks_params(["intact"], {NAME: np.array([0.2])})     # control: no effect at another level


# ------------------------------------------------------------------ on the real rows
@pytest.fixture(scope="module")
def problem(units):
    return RD.multilevel_problem(config(), YAMAMOTO, None, units=units, levels=["L5-S1"])


def test_multilevel_problem_tries_the_candidate_and_reports_its_range(problem):
    assert NAME in problem.candidates
    base = problem.forward({})[0]
    inside = RD.sourced_candidates(problem, {"estimates": {NAME: 0.0}}, base)[NAME]
    assert inside["inside"] and inside["rows_worse_at_estimate"] == []
    far = RD.sourced_candidates(problem, {"estimates": {NAME: 1.2}}, base)[NAME]
    assert not far["inside"]
    # the model's L5-S1 axial rotation is already too large on this set: a much softer disc makes it worse
    assert any("axial_rotation" in r for r in far["rows_worse_at_estimate"])
    r = {"decision": "unexplained", "best_candidate": NAME, "p_value": 0.4}
    text = RD.why_not_named(r, {0.5: "unexplained", 1.0: "unexplained"}, "independent", {NAME: far})
    assert f"{NAME} (estimate 1.2 outside its sourced range" in text and "axial_rotation" in text
    # control: without a sourced candidate the text says none was found
    assert "no candidate with a sourced magnitude range was found" in RD.why_not_named(r, {1.0: "x"}, "independent")


def test_power_check_names_a_large_planted_candidate_and_not_one_at_its_sourced_size(problem):
    """Planted tables (model at the magnitude + noise at the rows' sigma): at the sourced bound the candidate moves the
    four L5-S1 rows by a fraction of their sigma and is never named; the control, planted at the fit's upper bound (a
    disc of 2.5 times the height), is named in some tables, so the count can be non-zero."""
    from lumbar.discovery.detect import discovery_settings
    s = discovery_settings(config())
    rec = RD.sourced_candidates(problem, {"estimates": {NAME: fx.EFFECTS[NAME].bounds[1]}}, problem.forward({})[0])
    RD.sourced_power(problem, rec, s, n_tables=6, cache={})
    pw = rec[NAME]["power"]
    assert pw["sourced_bound"]["magnitude"] == pytest.approx(fx.sourced_range(NAME)[0])    # the end farther from 0
    assert pw["sourced_bound"]["named"] == 0 and pw["sourced_bound"]["tables"] == 6
    assert pw["estimate"]["magnitude"] == fx.EFFECTS[NAME].bounds[1] and pw["estimate"]["named"] >= 1
    text = RD.why_not_named({"decision": "unexplained"}, {1.0: "unexplained"}, "independent", rec)
    assert "planted at its sourced bound" in text and "named in 0 of 6 tables" in text
