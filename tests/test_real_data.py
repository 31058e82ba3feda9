"""Real misses posed to the discovery (lumbar.discovery.real_data): the other levels' ROM, the in-vivo IDP with the
lying postures, the facet share of compression, the decision at other spreads and the extended summary.

The in-vivo tables below are TEST FIXTURES of the muscle model's output schemas, never data."""
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lumbar.discovery import DiscoveryInputError
from lumbar.discovery import real_data as RD
from lumbar.inputs.config import ConfigError, load_config

ROOT = Path(__file__).resolve().parents[1]
YAMAMOTO = ROOT / "data" / "experiments" / "yamamoto1989_levels_original_text.csv"
LYING = ROOT / "data" / "in_vivo" / "wilke1999_idp_lying_original_text.csv"
LITERATURE = ROOT / "data" / "load_sharing" / "load_sharing_literature.csv"
LEVELS = ["L5-S1"]


def config(**disc):
    d = {"grid_points": 5, "null_specimens": 0, "n_bootstrap": 199}
    d.update(disc)
    return {"seed": 7, "characteristics": {"data_dir": str(ROOT / "data" / "characteristics")},
            "geometry": {"kind": "visible_human", "path": str(ROOT / "data" / "geometry" / "visible_human_lss")},
            "discovery": d}


@pytest.fixture(scope="module")
def units():
    return RD.level_units(config(), LEVELS)


@pytest.fixture(scope="module")
def ml_problem(units):
    return RD.multilevel_problem(config(), YAMAMOTO, None, units=units, levels=LEVELS)


# ------------------------------------------------------------------ the other levels' ROM
def test_yamamoto_rows_leave_out_the_calibrated_level():
    rows = RD.yamamoto_other_levels(YAMAMOTO, "L4-L5")
    assert len(rows) == 16 and "L4-L5" not in set(rows["level"])
    assert set(rows["level"]) == {"L1-L2", "L2-L3", "L3-L4", "L5-S1"}
    # control: another calibrated level leaves L4-L5 in and that level out
    other = RD.yamamoto_other_levels(YAMAMOTO, "L5-S1")
    assert "L4-L5" in set(other["level"]) and "L5-S1" not in set(other["level"])


def test_multilevel_forward_equals_the_range_of_motion_path(units, ml_problem):
    """The batched forward (FsuVariants, both sides averaged) equals lumbar.experiments.fsu.range_of_motion on the same
    unit (the path of results/tables/multilevel_rom.csv's bands); a one-sided reading would differ."""
    from lumbar.experiments.fsu import range_of_motion
    from lumbar.experiments.validation import MULTILEVEL_DIRECTIONS
    base = ml_problem.forward({})[0]
    dirs = [d for ds in MULTILEVEL_DIRECTIONS.values() for d in ds]
    rom = range_of_motion(units["L5-S1"].fsu, [10.0], dirs, ["intact"])
    by = dict(zip(rom["direction"], rom["rom_deg"]))
    ref = [np.mean([by[d] for d in MULTILEVEL_DIRECTIONS[yd]]) for yd in ml_problem.keys["direction"]]
    np.testing.assert_allclose(base, ref, atol=1e-6)
    one_side = [by[MULTILEVEL_DIRECTIONS[yd][0]] for yd in ml_problem.keys["direction"]]
    assert np.max(np.abs(np.array(one_side) - ref)) > 1e-4          # control: the sides differ on this geometry


def test_multilevel_candidates_vanish_at_zero_and_move_the_rows(ml_problem):
    """Every candidate at 0 gives the model without it (bit for bit); the ligament prestrain moves the intact rows,
    the vertebral-arch offset (acting only after the arches are removed) does not: the rows are the intact stage."""
    base = ml_problem.forward({})
    zero = ml_problem.forward({c: np.zeros(1) for c in ml_problem.candidates})
    np.testing.assert_array_equal(base, zero)
    pre = ml_problem.forward({"ligament_prestrain": np.array([0.04])})
    assert np.nanmax(np.abs(pre - base)) > 0.05
    off = ml_problem.forward({"va_neutral_offset": np.array([0.05])})
    np.testing.assert_allclose(off, base, atol=1e-9)


def test_multilevel_sigma_adds_the_model_band_and_scales_only_the_assumed_part(ml_problem):
    rows = ml_problem.keys.assign(sim_band_low=1.0, sim_band_high=1.0 + 2 * RD.Z90 * 0.3)
    sd = RD.model_band_sd_levels(ml_problem.keys, rows)
    np.testing.assert_allclose(sd, 0.3)
    assert np.all(RD.model_band_sd_levels(ml_problem.keys, None) == 0)
    p = ml_problem
    p.meta["model_sd"] = sd
    half, double = RD.with_spread(p, 0.5), RD.with_spread(p, 2.0)
    a = p.meta["sigma_assumed"]
    np.testing.assert_allclose(half.sigma, np.hypot(0.5 * a, 0.3))
    np.testing.assert_allclose(double.sigma, np.hypot(2.0 * a, 0.3))
    assert half.sigma.min() >= 0.3                            # the model's own spread is not scaled away


def test_localise_names_the_row_of_the_largest_z(ml_problem):
    base = ml_problem.forward({})[0]
    where, z = RD.localise(ml_problem, base)
    i = int(np.argmax(np.abs((base - ml_problem.y) / ml_problem.sigma)))
    assert where == f"level L5-S1, direction {ml_problem.keys['direction'].iat[i]}, moment_nm 10.0"
    # control: moving the miss to another row moves the label
    b2 = ml_problem.y.copy()
    j = (i + 1) % ml_problem.n
    b2[j] += 50 * ml_problem.sigma[j]
    assert RD.localise(ml_problem, b2)[0].endswith(f"direction {ml_problem.keys['direction'].iat[j]}, moment_nm 10.0")


def test_bad_yamamoto_table_is_refused_naming_file_and_column(tmp_path):
    p = tmp_path / "y.csv"
    pd.read_csv(YAMAMOTO).drop(columns=["value_deg"]).to_csv(p, index=False)
    with pytest.raises(DiscoveryInputError, match=r"y\.csv: column\(s\) \['value_deg'\] missing"):
        RD.yamamoto_other_levels(p, "L4-L5")
    t = pd.read_csv(YAMAMOTO)
    t.loc[0, "direction"] = "sideways"
    t.to_csv(p, index=False)
    with pytest.raises(DiscoveryInputError, match=r"column 'direction': \['sideways'\] not understood"):
        RD.yamamoto_other_levels(p, "L4-L5")


# ------------------------------------------------------------------ in vivo with the lying postures
def _muscle_fixture(offset_mpa=0.0):
    """TEST FIXTURE of the muscle model's tables (in_vivo_validation.csv, muscle_model_segment_loads.csv schemas)."""
    acts = ["extension_19deg", "upright_standing", "crate_close", "flexion_36deg"]
    F = np.array([1000.0, 700.0, 1600.0, 1300.0])
    M = np.array([-8.0, 1.0, 12.0, 35.0])
    per_n = 0.7e-3
    val = pd.DataFrame({"activity": acts, "idp_sim_mpa": per_n * F, "idp_in_vivo_mpa": per_n * F + offset_mpa,
                        "converged": True, "source": "TEST FIXTURE", "kind": "surrogate"})
    loads = pd.DataFrame({"level": "L4-L5", "activity": acts, "compressive_n": F, "shear_n": 0.0, "moment_nm": M,
                          "converged": True})
    return val, loads, per_n


def _compression(rest_n=40.0):
    return pd.DataFrame({"force_n": [0.0, 500.0, 1000.0], "converged": [True, True, True],
                         "disc_axial_force_n": [rest_n, 520.0, 1000.0], "facet_share": [0.001, 0.004, 0.0072]})


def test_rest_disc_force_reads_the_unloaded_row_and_refuses_a_table_without_it():
    assert RD.rest_disc_force(_compression(40.5)) == 40.5
    with pytest.raises(DiscoveryInputError, match="column 'disc_axial_force_n' missing"):
        RD.rest_disc_force(_compression().drop(columns=["disc_axial_force_n"]))
    with pytest.raises(DiscoveryInputError, match="no converged row at force_n = 0"):
        RD.rest_disc_force(_compression().iloc[1:])


def test_lying_rows_are_the_unit_at_rest_with_the_muscle_models_idp_per_newton():
    """The lying state: the passive unit at rest through the muscle model's paper-2 IDP formula at moment 0
    (0.85 F / (0.66 A), A = 18 cm^2), whatever the muscle rows did; a failed muscle model still poses them."""
    val, loads, per_n = _muscle_fixture()
    v, sl = RD.lying_tables(LYING, val, loads, 40.0)
    ly = v[v["activity"].str.startswith("lying")]
    assert list(ly["activity"]) == ["lying_prone", "lying_lateral"]
    np.testing.assert_allclose(ly["idp_sim_mpa"], 0.85 * 40.0 / (0.66 * 18e-4) / 1e6)
    # the disc area enters as the formula says (half the area, twice the pressure)
    v_half, _ = RD.lying_tables(LYING, val, loads, 40.0, area_m2=9e-4)
    np.testing.assert_allclose(v_half["idp_sim_mpa"].iloc[4:], 2 * ly["idp_sim_mpa"])
    # no converged muscle posture: the lying rows are still posed, the muscle rows marked not converged
    v_none, _ = RD.lying_tables(LYING, val.assign(converged=False), loads, 40.0)
    np.testing.assert_allclose(v_none["idp_sim_mpa"].iloc[4:], ly["idp_sim_mpa"])
    assert not v_none["converged"].iloc[:4].any() and v_none["converged"].iloc[4:].all()
    np.testing.assert_allclose(ly["idp_in_vivo_mpa"], [0.1, 0.12])     # the cited rows
    s = sl[sl["activity"].str.startswith("lying")]
    assert (s["moment_nm"] == 0).all() and (s["compressive_n"] == 40.0).all()
    # control: the rest force moves the lying rows and only them
    v2, _ = RD.lying_tables(LYING, val, loads, 80.0)
    assert np.allclose(v2["idp_sim_mpa"].iloc[:4], v["idp_sim_mpa"].iloc[:4])
    np.testing.assert_allclose(v2["idp_sim_mpa"].iloc[4:], 2 * v["idp_sim_mpa"].iloc[4:])


def _lying_problem(tmp_path, offset_mpa):
    val, loads, _ = _muscle_fixture(offset_mpa)
    pv, pl, pc = tmp_path / "v.csv", tmp_path / "l.csv", tmp_path / "c.csv"
    val.to_csv(pv, index=False)
    loads.to_csv(pl, index=False)
    _compression().to_csv(pc, index=False)
    cfg = config(in_vivo_sd_mpa=0.05)
    return cfg, RD.in_vivo_lying_problem(cfg, pv, pl, LYING, pc)


def test_run_case_decides_at_each_spread_and_writes_the_case(tmp_path):
    """A fixture whose muscle rows match the model: the lying rows are then the largest miss; the case's folder holds
    the discovery outputs and real_case.json with the decision at half and double the assumed spread."""
    cfg, p = _lying_problem(tmp_path, 0.0)
    assert p.n == 6
    rec = RD.run_case("in_vivo_lying", p, cfg, tmp_path / "case", "fixture")
    assert rec["largest_miss"].startswith("activity lying_")
    assert rec["largest_z"] < 0                                          # the model below the measured 0.1 MPa
    for f in ("discovery.json", "scenarios.csv", "section.md", "real_case.json"):
        assert (tmp_path / "case" / f).is_file()
    saved = json.loads((tmp_path / "case" / "real_case.json").read_text())
    assert saved["decision"] == json.loads((tmp_path / "case" / "discovery.json").read_text())["decision"]
    assert {"decision_half_spread", "decision_double_spread", "why_not_named", "what_would_decide"} <= set(saved)
    assert saved["adopted"] is False and saved["candidates_tried"]


def test_uniform_offset_is_named_at_the_assumed_spread_but_not_adopted(tmp_path):
    """A planted uniform IDP offset on every row (muscle and lying): the preload candidate (a uniform offset on this
    experiment) is named; with adopted_effects empty it is not adopted. Control: no offset, nothing named."""
    cfg, p = _lying_problem(tmp_path, 0.0)
    p.y = p.y + 0.25
    rec = RD.run_case("in_vivo_lying", p, cfg, tmp_path / "a", "fixture")
    r = json.loads((tmp_path / "a" / "discovery.json").read_text())
    assert r["named_effect"] == "axial_preload" and rec["adopted"] is False and rec["why_not_named"] == ""
    cfg0, p0 = _lying_problem(tmp_path, 0.0)
    p0.y = p0.forward({})[0].copy()
    RD.run_case("in_vivo_lying", p0, cfg0, tmp_path / "b", "fixture")
    assert json.loads((tmp_path / "b" / "discovery.json").read_text())["named_effect"] is None


# ------------------------------------------------------------------ facet share
def test_facet_share_row_reads_the_share_column(tmp_path):
    c = tmp_path / "c.csv"
    _compression().to_csv(c, index=False)
    r = RD.facet_share_rows(LITERATURE, c)
    assert r["measured_pct"].iat[0] == 16 and r["model_pct"].iat[0] == pytest.approx(0.72)
    assert r["z"].iat[0] == pytest.approx((0.72 - 16) / RD.FACET_SHARE_ASSUMED_SD)
    rec = RD.facet_share_case(LITERATURE, c, tmp_path / "fs", config())
    assert "too few rows" in rec["decision"] and rec["why_not_named"].startswith("power")
    assert rec["candidates_tried"].startswith("none: no library candidate acts on the facet share")
    assert abs(rec["z_half_spread"]) == pytest.approx(2 * abs(rec["largest_z"]))
    # control: a model share at the measured value has z 0
    _compression().assign(facet_share=0.16).to_csv(c, index=False)
    assert RD.facet_share_rows(LITERATURE, c)["z"].iat[0] == pytest.approx(0.0)
    _compression().drop(columns=["facet_share"]).to_csv(c, index=False)
    with pytest.raises(DiscoveryInputError, match="column 'facet_share' missing"):
        RD.facet_share_rows(LITERATURE, c)


# ------------------------------------------------------------------ why nothing was named; the summary; adoption
@pytest.mark.parametrize("r, decisions, role, start", [
    ({"decision": "unexplained"}, {}, "calibration target", "circularity"),
    ({"decision": "nothing named", "too_few_rows": True, "n_scenarios": 1}, {}, "independent", "power: 1 row(s)"),
    ({"decision": "unexplained", "best_candidate": "itl", "p_value": 0.3}, {}, "independent", "no candidate"),
    ({"decision": "nothing named"}, {}, "independent", "power: the table does not differ"),
    ({"decision": "named: itl", "named_effect": "itl"}, {}, "independent", ""),
])
def test_why_not_named_by_kind(r, decisions, role, start):
    assert RD.why_not_named(r, decisions, role).startswith(start)


def test_why_not_named_flags_a_spread_dependent_decision():
    r = {"decision": "unexplained"}
    assert "spread:" in RD.why_not_named(r, {0.5: "unexplained", 1.0: "unexplained", 2.0: "nothing named"}, "x")
    assert "spread:" not in RD.why_not_named(r, {0.5: "unexplained", 1.0: "unexplained", 2.0: "unexplained"}, "x")


def _discovery_json(path, decision="unexplained", too_few=False):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({
        "n_scenarios": 4, "gap_before": 2.0, "named_effect": None, "p_value": 0.2, "parameter_estimate": None,
        "gap_after": 2.0, "decision": decision, "decision_reasons": ["a reason"], "best_nuisance": None,
        "best_nuisance_description": "nominal model", "nuisance": {}, "gap_specimen_mean": 2.0, "gap_nuisance": 2.0,
        "best_candidate": "itl", "best_candidate_estimate": 0.1, "too_few_rows": too_few, "identifiability": {},
        "estimates": {"itl": 0.1}, "measured": "fixture"}))
    pd.DataFrame({"stage": ["intact"] * 2, "direction": ["flexion", "extension"], "measured": [1.0, 2.0],
                  "sigma": [1.0, 1.0], "z_before": [0.5, -3.0]}).to_csv(path.parent / "scenarios.csv", index=False)
    return path


def test_summary_marks_the_calibration_target_and_joins_the_posed_cases(tmp_path):
    intact = _discovery_json(tmp_path / "intact_rom" / "discovery.json")
    va = _discovery_json(tmp_path / "va_artefact" / "discovery.json", "nothing named: too few rows", True)
    c = tmp_path / "c.csv"
    _compression().to_csv(c, index=False)
    RD.facet_share_case(LITERATURE, c, tmp_path / "facet_share", config())
    t = RD.real_misses_summary([intact, va], [tmp_path / "facet_share" / "real_case.json"], {"adopted_effects": []})
    assert list(t.columns) == list(RD.SUMMARY_COLUMNS)
    assert list(t["dataset"]) == ["intact_rom", "va_artefact", "facet_share"]
    row = t.set_index("dataset")
    assert row.loc["intact_rom", "decision"] == "calibration target: not posed"
    assert "kept for reference: unexplained" in row.loc["intact_rom", "note"]
    assert row.loc["intact_rom", "largest_miss"] == "stage intact, direction extension"
    # control: an independent case keeps its decision; too few rows is the same at every spread
    assert row.loc["va_artefact", "decision"] == row.loc["va_artefact", "decision_double_spread"] != ""
    assert row.loc["va_artefact", "decision"].startswith("nothing named")
    assert not t["adopted"].any() and t["note"].str.contains("adopted: no").all()


def test_adopted_effects_key_exists_is_empty_and_refuses_an_entry():
    assert load_config({})["adopted_effects"] == []
    assert load_config(ROOT / "config" / "config.yaml")["adopted_effects"] == []
    with pytest.raises(ConfigError, match="adopted_effects"):
        load_config({"adopted_effects": ["ligament_prestrain"]})


def test_candidate_sensitivity_separates_a_candidate_that_moves_the_rows_from_one_that_does_not(ml_problem):
    base = ml_problem.forward({})[0]
    s = RD.candidate_sensitivity(ml_problem, base)
    assert set(s) == set(ml_problem.candidates)
    assert s["ligament_prestrain"]["rows_moved"] >= 1 and s["ligament_prestrain"]["largest_abs_dz"] > 0.1
    assert s["va_neutral_offset"]["rows_moved"] == 0 and s["va_neutral_offset"]["largest_abs_dz"] < 1e-6


def test_gap_by_group_is_the_rms_z_per_level(ml_problem):
    base = ml_problem.y + ml_problem.sigma * np.where(np.arange(ml_problem.n) % 2 == 0, 2.0, 0.0)
    g = RD.gap_by_group(ml_problem, base)
    assert list(g) == ["L5-S1"] and g["L5-S1"] == pytest.approx(np.sqrt(2.0))


def test_report_text_reads_every_number_from_the_summary(tmp_path):
    from lumbar.report.real_loop import real_misses_markdown
    intact = _discovery_json(tmp_path / "intact_rom" / "discovery.json")
    va = _discovery_json(tmp_path / "va_artefact" / "discovery.json", "nothing named: too few rows", True)
    t = RD.real_misses_summary([intact, va], [], {"adopted_effects": []})
    md = real_misses_markdown(t)
    assert "compared with 2 real dataset(s); 1 of them a calibration target" in md
    assert "named an effect on 0 and 0 effect(s) were adopted" in md
    assert md.count("\n| ") == 3 and "calibration target: not posed" in md and "| -3.00 |" in md
    # control: a named row changes the count
    t.loc[1, "named_effect"] = "itl"
    assert "named an effect on 1 " in real_misses_markdown(t)
    with pytest.raises(ValueError, match=r"column\(s\) \['adopted'\] missing"):
        real_misses_markdown(t.drop(columns=["adopted"]))
