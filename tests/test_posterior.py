"""The calibration as a regularised inverse problem: sourced priors (lumbar.experiments.priors), the Laplace posterior
and the linearised prediction bands (lumbar.experiments.posterior), the internal-load rows of the real-data
scoreboard (lumbar.experiments.validation.internal_load_rows). Analytic cases, limits and controls that fail for the
wrong mechanism."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from lumbar.experiments import posterior as P
from lumbar.experiments import priors as PR
from lumbar.experiments import validation as V
from lumbar.inputs.characteristics import SoftplusLaw, load_characteristic_set


# ------------------------------------------------------------------ Laplace posterior: the linear-Gaussian case
def _linear_posterior(A, y, sigma, centre, spread, q=None):
    """Posterior of y = A q + noise(sigma), q ~ N(centre, spread^2), through laplace_posterior at the exact MAP."""
    A, y = np.asarray(A, float), np.asarray(y, float)
    centre, spread = np.asarray(centre, float), np.asarray(spread, float)
    H = A.T @ A / sigma**2 + np.diag(1.0 / spread**2)
    q_map = np.linalg.solve(H, A.T @ y / sigma**2 + centre / spread**2) if q is None else q
    J = np.vstack([A / sigma, np.diag(1.0 / spread)])
    r = np.concatenate([(A @ q_map - y) / sigma, (q_map - centre) / spread])
    names = [f"p{j}" for j in range(A.shape[1])]
    rnames = [f"row {i}" for i in range(len(y))] + [f"prior {n}" for n in names]
    post = P.laplace_posterior(names, q_map, centre, spread, np.full(len(names), -1e9), np.full(len(names), 1e9), J,
                               r, rnames, n_data=len(y))
    return post, np.linalg.inv(H)


def test_laplace_posterior_equals_the_analytic_gaussian_posterior():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(4, 3))
    post, cov = _linear_posterior(A, rng.normal(size=4), 0.3, np.zeros(3), np.array([1.0, 0.5, 2.0]))
    np.testing.assert_allclose(post.cov, cov, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(post.sd, np.sqrt(np.diag(cov)), rtol=1e-10)


def test_band_narrows_with_the_data_spread_and_widens_with_the_prior_spread():
    A = np.array([[1.0, 0.5], [0.2, 1.0], [1.0, -1.0]])
    g = np.array([[1.0, 1.0]])                       # a prediction that depends on both parameters
    base = _linear_posterior(A, np.ones(3), 0.5, np.zeros(2), np.ones(2))[0].band(g)[0]
    tight_data = _linear_posterior(A, np.ones(3), 0.1, np.zeros(2), np.ones(2))[0].band(g)[0]
    wide_prior = _linear_posterior(A, np.ones(3), 0.5, np.zeros(2), np.full(2, 5.0))[0].band(g)[0]
    assert tight_data < base < wide_prior
    # limits: no data information -> the prior's own spread; a prediction of nothing -> 0
    none = _linear_posterior(np.zeros((3, 2)), np.ones(3), 0.5, np.zeros(2), np.array([2.0, 3.0]))[0]
    assert none.band(g)[0] == pytest.approx(math.hypot(2.0, 3.0))
    assert none.band(np.zeros((1, 2)))[0] == 0.0


def test_moved_by_names_the_row_that_pulls_and_stayed_at_prior_the_parameter_no_row_touches():
    # p0 is measured by row 0 only (far from its prior), p1 by nothing
    A = np.array([[1.0, 0.0], [0.0, 0.0]])
    post, _ = _linear_posterior(A, np.array([3.0, 0.0]), 0.2, np.zeros(2), np.ones(2))
    assert post.moved_by(0)[0].startswith("row 0")
    assert post.moved_by(1) == []
    assert list(post.stayed_at_prior()) == [False, True]
    t = P.posterior_table(post)
    assert bool(t.loc[0, "data_moved_it"]) and not bool(t.loc[1, "data_moved_it"])
    assert t.loc[0, "spread_ratio"] < 0.3 and t.loc[1, "spread_ratio"] == pytest.approx(1.0)
    # control: the same parameter with no data row keeps its prior: a test built to fail if moved_by ignored signs
    post2, _ = _linear_posterior(A, np.array([0.0, 0.0]), 0.2, np.zeros(2), np.ones(2))
    assert post2.moved_by(0) == []


def test_covariance_table_round_trip():
    post, cov = _linear_posterior(np.eye(2), np.ones(2), 0.5, np.zeros(2), np.ones(2))
    names, C = P.read_covariance(P.covariance_table(post))
    assert names == post.names
    np.testing.assert_allclose(C, cov, rtol=1e-12)


def test_linearised_band_of_a_linear_prediction_is_exact():
    cov = np.array([[0.04, 0.01], [0.01, 0.09]])
    g = np.array([[2.0, -1.0], [0.5, 3.0]])

    def predict(q):
        return g @ np.asarray(q, float)

    def shift(q, name, d):
        q = np.array(q, float)
        q[int(name[1:])] += d
        return q

    y, sd, G = P.linearised_band(predict, np.zeros(2), ["p0", "p1"], cov, shift)
    np.testing.assert_allclose(G, g, rtol=1e-9)
    np.testing.assert_allclose(sd, np.sqrt(np.einsum("ij,jk,ik->i", g, cov, g)), rtol=1e-9)


# ------------------------------------------------------------------ the Remus et al. (2021) prior
MAT = {"reference_strain": -0.02, "transition_strain": 0.06, "stiffness_n": 200.0, "cross_section_mm2": 10.0}


def test_remus_as_softplus_reproduces_the_uw_law_of_the_fibres():
    lengths = np.array([0.010, 0.012, 0.015])
    law, info = PR.remus_as_softplus([("G", lengths)], {"G": MAT})
    e = np.linspace(0.0, PR.REMUS_FIT_ELONGATION_M, 61)
    F = PR.remus_group_force(lengths, MAT, e)
    assert np.abs(PR.law_force(law, e) - F).max() <= 0.03 * F.max()
    assert info["fit_max_deviation_n"] <= 0.03 * F.max()
    # pre-elongation: the fibres' mean l_geometric - l0 = -reference strain x l_geometric (pre-stretched here)
    assert law.pre_elongation_m == pytest.approx(0.02 * lengths.mean(), rel=1e-9)
    # a slack ligament (positive reference strain) has a negative pre-elongation
    slack, _ = PR.remus_as_softplus([("G", lengths)], {"G": {**MAT, "reference_strain": 0.1}})
    assert slack.pre_elongation_m < 0


def test_remus_group_force_is_zero_until_slack_and_linear_beyond_transition():
    L = np.array([0.02])
    m = {**MAT, "reference_strain": 0.0}
    e = np.array([0.0, 0.02 * 0.03, 0.02 * 0.10, 0.02 * 0.20])
    F = PR.remus_group_force(L, m, e)
    assert F[0] == 0.0
    assert F[1] == pytest.approx(200.0 * 0.03**2 / (2 * 0.06))
    assert F[3] - F[2] == pytest.approx(200.0 * 0.10)


def _law(a, pre_mm=1.0, L=0.01):
    return SoftplusLaw(a, -2.0, 0.0, 1.0, 100.0 * pre_mm * 1e-3 / L, law_length_m=L)


def test_ligament_spreads_follow_the_disagreement_of_the_two_sources():
    a = {"ALL": _law(10.0), "CL": _law(10.0), "ISL": _law(10.0, 2.0), "ITL": _law(10.0)}
    b = {"ALL": _law(10.0), "CL": _law(100.0), "ISL": _law(1000.0, 0.0), "ITL": _law(1.0e4)}
    dis = PR.source_disagreement(a, b)
    s = PR.ligament_spreads(dis)
    # agreeing sources: the floor; a factor of 10: one decade; a factor of 100 and 2 mm: two decades, 2 mm
    assert s["ALL:scale"] == PR.MIN_SCALE_LOG10_SD
    assert s["ALL:pre_elongation"] == PR.MIN_PRE_ELONGATION_SD_MM
    assert s["CL:scale"] == pytest.approx(1.0, rel=1e-6)
    assert s["ISL:scale"] == pytest.approx(2.0, rel=0.05)
    assert s["ISL:pre_elongation"] == pytest.approx(2.0, rel=1e-9)
    # the ITL's second source is no calibration: its 3-decade disagreement is replaced by the calibrated kinds' median
    assert s["ITL:scale"] == pytest.approx(1.0, rel=1e-6)


def test_default_spreads_cover_every_fit_parameter_and_reject_an_unknown_one():
    names = ["ALL:scale", "ALL:pre_elongation", "facet_stiffness", "disc_shear", "disc_torque:flexion"]
    sd = PR.default_spreads(names, np.zeros(5), np.array([0, 0, 0, 0.4, 0]))
    assert sd[3] == pytest.approx(0.1)
    assert np.all(sd > 0)
    with pytest.raises(ValueError, match="no default prior spread"):
        PR.default_spreads(["bogus"], np.zeros(1), np.ones(1))


@pytest.fixture(scope="module")
def vh_geometry():
    from lumbar.geometry import load_geometry
    return load_geometry("visible_human", path=_vh_path(), levels=["L4-L5"])


def _vh_path():
    from lumbar.inputs.resources import data_dir
    return data_dir() / "geometry" / "visible_human_lss"


def test_calibration_prior_is_the_remus_law_of_the_same_fibres(vh_geometry):
    from lumbar.experiments.calibration import calibration_prior
    from lumbar.geometry.visible_human import read_uw_materials

    path = _vh_path()
    cs, prov, spreads = calibration_prior(None, vh_geometry, "L4-L5", path, "remus2021")
    mats = read_uw_materials(path, "L4-L5")
    for kind in ("ALL", "CL", "ISL"):
        groups = PR.level_fibre_groups(vh_geometry.levels["L4-L5"], kind)
        e = np.array([3e-3])
        remus = np.mean([PR.remus_group_force(L, mats[n], e) for n, L in groups])
        assert float(PR.law_force(cs.ligaments[kind], e)[0]) == pytest.approx(float(remus), rel=0.05)
        assert f"{kind}:scale" in spreads and f"{kind}:pre_elongation" in spreads
    assert set(prov["prior"]) == {"remus2021"}
    t3, _, _ = calibration_prior(None, vh_geometry, "L4-L5", path, "table3")
    assert t3.ligaments["ALL"].a != cs.ligaments["ALL"].a       # control: the switch changes the centre
    with pytest.raises(ValueError, match="ligament prior"):
        calibration_prior(None, vh_geometry, "L4-L5", path, "remus")


def test_shift_parameter_moves_one_parameter_in_fit_units():
    from lumbar.experiments.calibration import shift_parameter
    cs = load_characteristic_set("calibrated")
    cs = dataclasses.replace(cs, ligaments={**cs.ligaments, "ALL": dataclasses.replace(cs.ligaments["ALL"],
                                                                                          law_length_m=0.01)})
    s = shift_parameter(cs, "ALL:scale", 1.0)
    assert s.ligaments["ALL"].a == pytest.approx(10 * cs.ligaments["ALL"].a)
    assert s.ligaments["ALL"].c == pytest.approx(10 * cs.ligaments["ALL"].c)
    p = shift_parameter(cs, "ALL:pre_elongation", 0.5)
    assert p.ligaments["ALL"].pre_elongation_m - cs.ligaments["ALL"].pre_elongation_m == pytest.approx(0.5e-3)
    f = shift_parameter(cs, "facet_stiffness", math.log10(2.0))
    assert f.facet.stiffness == pytest.approx(2 * cs.facet.stiffness)
    d = shift_parameter(cs, "disc_torque:extension", math.log10(3.0))
    p1, p2, p3 = cs.disc.torque["extension"]
    assert d.disc.torque["extension"] == pytest.approx((3 * p1, p2, 3 * p3))
    assert d.disc.torque["flexion"] == cs.disc.torque["flexion"]


# ------------------------------------------------------------------ internal loads in the real-data scoreboard
def _curves(facet_ext=60.0, isl=50.0, ssl=15.0, cl=2.0, fl=1.0):
    rows = []
    for d in ("flexion", "extension", "lateral_bending_right", "axial_rotation_left"):
        for M in (7.5, 10.0):
            rows.append({"stage": "intact", "direction": d, "moment_nm": M, "converged": True,
                         "facet_left_contact_n": facet_ext if d == "extension" else 10.0, "facet_right_contact_n": 5.0,
                         "ISL_tension_n": isl, "SSL_tension_n": ssl, "CL_moment_y_nm": -cl, "FL_moment_y_nm": -fl})
    return pd.DataFrame(rows)


def test_internal_load_rows_judge_facets_independently_and_mark_fit_constraints():
    from lumbar.experiments.admissibility import read_literature
    lit = read_literature()
    comp = pd.DataFrame({"force_n": [0.0, 1000.0], "facet_share": [0.0, 0.1]})
    rows = pd.DataFrame(V.internal_load_rows(_curves(), comp, lit))
    facet = rows[rows["quantity"] == "facet contact force per joint"]
    assert set(facet["role"]) == {V.INTERNAL} and len(facet) == 4
    assert set(rows.loc[rows["quantity"] != "facet contact force per joint", "role"]) == {V.CONSTRAINT}
    ext = facet[facet["condition"].str.startswith("extension")].iloc[0]
    assert ext["sim"] == 60.0 and ext["within"]
    # the band is mean +- 2 SD of the in-vitro row (51.5 +- 39 N)
    assert ext["measured_high"] == pytest.approx(51.5 + 2 * 39.0)
    # controls: a facet force beyond the band, an ISL weaker than the SSL, the flavum ahead of the capsules fail
    bad = pd.DataFrame(V.internal_load_rows(_curves(facet_ext=200.0, isl=5.0, ssl=50.0, cl=1.0, fl=2.0), comp, lit))
    assert not bad.loc[bad["condition"].str.startswith("extension"), "within"].iloc[0]
    assert not bad.loc[bad["quantity"] == "ISL fraction of the ISL + SSL force", "within"].iloc[0]
    assert not bad.loc[bad["quantity"] == "capsular over flavum moment", "within"].iloc[0]


def test_scoreboard_band_columns_come_from_the_band_table_and_never_change_within():
    rows = [{"quantity": "L4-L5 ROM", "condition": "intact flexion 10 N*m", "unit": "deg", "sim": 7.0, "measured": 8.9,
             "measured_low": np.nan, "measured_high": np.nan, "kind": "original_text", "source": "s", "within": True,
             "tolerance_rule": "r", "set": "calibrated", "role": V.INDEPENDENT, "note": ""},
            {"quantity": "L4-L5 ROM", "condition": "intact flexion 10 N*m", "unit": "deg", "sim": 2.0, "measured": 8.9,
             "measured_low": np.nan, "measured_high": np.nan, "kind": "original_text", "source": "s", "within": False,
             "tolerance_rule": "r", "set": "paper_table3_as_published", "role": V.INDEPENDENT, "note": ""}]
    bands = pd.DataFrame({"direction": ["flexion"], "moment_nm": [10.0], "quantity": ["rotation_deg"], "map": [7.0],
                          "sd": [0.2], "low90": [6.6], "high90": [7.4], "converged": [True]})
    df = V.scoreboard(rows, bands)
    assert (df.loc[0, "sim_band_low"], df.loc[0, "sim_band_high"]) == (6.6, 7.4)
    assert np.isnan(df.loc[1, "sim_band_low"])              # another set has no posterior band
    assert list(df["within"]) == [True, False]
    # the posterior draws: the share of them inside the row's acceptance interval (25 % of 8.9: 6.675-11.125)
    draws = pd.DataFrame({"direction": "flexion", "moment_nm": 10.0, "quantity": "rotation_deg", "draw": range(4),
                          "value": [6.0, 7.0, 7.2, np.nan]})
    rows[0]["tolerance_rule"] = rows[1]["tolerance_rule"] = "measured +- 25 %"
    df = V.scoreboard(rows, bands, draws)
    assert df.loc[0, "p_within_posterior"] == pytest.approx(2 / 3)    # the draw that did not converge is left out
    assert np.isnan(df.loc[1, "p_within_posterior"]) and list(df["within"]) == [True, False]


def test_curve_draws_table_keeps_the_judged_moments_and_the_draws_of_each_row():
    bands = pd.DataFrame({"direction": ["flexion"] * 3, "moment_nm": [5.0, 7.5, 10.0],
                          "quantity": ["SSL_tension_n"] * 3})
    Y = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])                  # 2 draws x 3 rows
    band = P.Band(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.array(["x"] * 3, dtype=object), 2, 0, Y)
    t = P.curve_draws_table(bands, band)
    assert list(t.columns) == list(P.DRAW_VALUE_COLUMNS) and sorted(set(t["moment_nm"])) == [7.5, 10.0]
    assert list(t[t["moment_nm"] == 10.0]["value"]) == [3.0, 6.0] and list(t["draw"][:2]) == [0, 1]
    assert P.curve_draws_table(bands, P.Band(*(np.zeros(3),) * 4, np.array(["x"] * 3), 0, 0)).empty


# ------------------------------------------------------------------ what the model adds over a trivial model
def _row(q, cond, sim, meas, within, role=V.INDEPENDENT, set_="calibrated"):
    return {"quantity": q, "condition": cond, "unit": "deg", "sim": sim, "measured": meas, "measured_low": np.nan,
            "measured_high": np.nan, "kind": "original_text", "source": "s", "within": within,
            "tolerance_rule": "measured +- 25 % (no range published)", "set": set_, "role": role, "note": ""}


def test_null_model_counts_copy_the_calibrated_level_and_the_mean_pressure():
    yam = pd.DataFrame({"level": ["L4-L5", "L4-L5"], "quantity": ["rom", "rom"], "direction": ["flexion", "extension"],
                        "value_deg": [8.9, 5.8]})
    rows = [_row("ROM, other levels", "L3-L4 flexion 10 N*m", 8.0, 8.0, True),      # null 8.9: within 25 %
            _row("ROM, other levels", "L5-S1 flexion 10 N*m", 9.0, 12.0, True),     # null 8.9: outside
            _row("ROM, other levels", "L5-S1 extension 10 N*m", 3.0, 7.8, False),   # null 5.8: outside
            _row("L4-L5 IDP in vivo", "standing", 0.5, 0.5, True),
            _row("L4-L5 IDP in vivo", "crate", 1.0, 1.8, False),
            _row("ROM, other levels", "L1-L2 flexion 10 N*m", 1.0, 5.8, False, role=V.TARGET)]   # not independent
    t = V.null_model_counts(pd.DataFrame(rows), yam).set_index("quantity")
    assert len(t) == 2                             # the model's own L4-L5 null needs the model's values
    lv = t.loc["ROM, other levels"]
    assert (lv["n_rows"], lv["model_within"], lv["null_within"]) == (3, 2, 1) and bool(lv["model_beats_null"])
    iv = t.loc["L4-L5 IDP in vivo"]            # null 1.15 MPa: outside both bands
    assert (iv["n_rows"], iv["model_within"], iv["null_within"]) == (2, 1, 0)
    # control: a model that is the null scores the null's count and does not beat it
    same = [dict(r, sim=v, within=abs(v - r["measured"]) <= 0.25 * r["measured"]) for r, v in
            zip(rows[:3], (8.9, 8.9, 5.8))]
    s = V.null_model_counts(pd.DataFrame(same), yam).iloc[0]
    assert s["model_within"] == s["null_within"] and not bool(s["model_beats_null"])


def test_table_bands_merge_only_into_the_calibrated_rows():
    from lumbar.experiments.l2s1 import with_bands as idp_bands
    from lumbar.experiments.stepwise_reduction import with_bands as rom_bands
    syn = pd.DataFrame({"set": ["calibrated", "rupp2015"], "stage": ["intact"] * 2, "direction": ["flexion"] * 2,
                        "moment_nm": [10, 10]})
    b = pd.DataFrame({"stage": ["intact"], "direction": ["flexion"], "moment_nm": [10.0], "map": [7.0], "sd": [0.1],
                      "low90": [6.8], "high90": [7.2]})
    out = rom_bands(syn, b)
    assert (out.loc[0, "rom_band_low"], out.loc[0, "rom_band_high"]) == (6.8, 7.2)
    assert np.isnan(out.loc[1, "rom_band_low"])
    assert np.isnan(rom_bands(syn, b.iloc[:0]).loc[0, "rom_band_low"])
    syn5 = pd.DataFrame({"set": ["calibrated", "nolte1990"], "muscle_setup": ["all"] * 2, "load_case": ["neutral"] * 2})
    b5 = pd.DataFrame({"muscle_setup": ["all"], "load_case": ["neutral"], "low90": [0.3], "high90": [0.4]})
    o5 = idp_bands(syn5, b5)
    assert o5.loc[0, "idp_band_high_mpa"] == 0.4 and np.isnan(o5.loc[1, "idp_band_low_mpa"])


def test_discovery_model_band_joins_the_row_spread_in_quadrature(tmp_path):
    from lumbar.discovery.problems import model_band_sd
    keys = pd.DataFrame({"stage": ["intact", "intact"], "direction": ["flexion", "extension"], "moment_nm": [10, 10]})
    p = tmp_path / "bands.csv"
    # the band the report shows (here the posterior draws', narrower than the linearised sd of 0.3) sets the spread
    pd.DataFrame({"stage": ["intact"], "direction": ["flexion"], "moment_nm": [10.0], "map": [7.0], "sd": [0.3],
                  "low90": [6.8], "high90": [7.129]}).to_csv(p, index=False)
    np.testing.assert_allclose(model_band_sd(keys, p), [0.329 / (2 * P.Z90), 0.0])   # no band: adds nothing
    np.testing.assert_allclose(model_band_sd(keys, None), [0.0, 0.0])
    # a table without band ends: the linearised sd
    pd.DataFrame({"stage": ["intact"], "direction": ["flexion"], "moment_nm": [10.0], "sd": [0.3]}).to_csv(p, index=False)
    np.testing.assert_allclose(model_band_sd(keys, p), [0.3, 0.0])


def test_null_model_with_the_models_own_calibrated_level():
    yam = pd.DataFrame({"level": ["L4-L5"], "quantity": ["rom"], "direction": ["flexion"], "value_deg": [8.9]})
    rows = [_row("ROM, other levels", "L3-L4 flexion 10 N*m", 8.0, 8.0, True)]
    t = V.null_model_counts(pd.DataFrame(rows), yam, model_calibrated_level={"flexion": 12.0})
    own = t[t["null_model"] == "model's L4-L5 copied"].iloc[0]
    assert own["null_within"] == 0 and own["model_within"] == 1          # 12 is outside 8 +- 25 %


def test_disc_torque_prior_does_not_count_the_disc_only_curve_a_second_time():
    """The disc torque scales' prior is centred on the disc-only fit, and the disc-only rows enter the likelihood as
    data (one observation per direction): the prior must add (almost) nothing to what those rows say, or one
    published curve counts twice. Precision of the rows of one direction about the scale (log10 units):
    (ln 10 / DATA_SD_REL)^2 (n rows, each weighted 1/sqrt(n)); the prior's: 1 / sd^2. Control: the former prior
    (the spread of a measured row) carried about half as much as the rows themselves."""
    from lumbar.experiments import priors as PR
    from lumbar.experiments.calibration.admissible import DATA_SD_REL
    rows = (math.log(10.0) / DATA_SD_REL) ** 2
    names = ["disc_torque:axial_rotation", "disc_torque:flexion"]
    sd = PR.default_spreads(names, np.zeros(2), np.ones(2), disc_data_directions={"axial_rotation"})
    assert (1.0 / sd[0] ** 2) / rows < 0.05
    assert (1.0 / math.log10(1.0 + DATA_SD_REL) ** 2) / rows > 0.5          # the double count it replaces
    # a direction without disc-only rows in the likelihood keeps the curve as its prior, at a measured row's spread
    assert sd[1] == pytest.approx(math.log10(1.0 + DATA_SD_REL))


# ------------------------------------------------------------------ checked bands: draws where the linearisation fails
def _shift1(q, name, d):
    q = np.array(q, float)
    q[int(name[1:])] += d
    return q


def _gauss(cov, n, seed=0):
    return np.random.default_rng(seed).multivariate_normal(np.zeros(len(cov)), cov, size=n)


def test_checked_band_keeps_a_linear_band_that_passes_its_check_and_runs_no_draw():
    cov = np.array([[0.04]])
    calls = []

    def predict(q):
        calls.append(1)
        return np.array([2.0 * q[0] + 5.0])

    b = P.checked_band(predict, np.zeros(1), ["p0"], cov, _shift1, lower=0.0, offsets=_gauss(cov, 64))
    assert b.n_draws == 0 and list(b.method) == [P.METHOD_LINEAR] and len(calls) == 2   # MAP + one step, no draw
    assert b.low90[0] == pytest.approx(5.0 - P.Z90 * 0.4) and b.high90[0] == pytest.approx(5.0 + P.Z90 * 0.4)


def test_checked_band_samples_a_positive_quantity_whose_linear_band_goes_negative():
    # y = exp(q), q ~ N(0, 0.8^2): the linear band 1 +- 1.645 * 0.8 reaches below 0, the true 90 % band is
    # exp(+-1.645 * 0.8) = [0.27, 3.73]
    s = 0.8
    cov = np.array([[s * s]])
    D = _gauss(cov, 4000, seed=1)
    b = P.checked_band(lambda q: np.exp(q), np.zeros(1), ["p0"], cov, _shift1, lower=0.0, offsets=D)
    assert b.method[0] == P.METHOD_BOUND and b.n_draws == 4000
    assert b.low90[0] == pytest.approx(np.exp(-P.Z90 * s), rel=0.1)
    assert b.high90[0] == pytest.approx(np.exp(P.Z90 * s), rel=0.1)
    # control: without the physical bound nothing flags the row and the impossible linear band stays
    c = P.checked_band(lambda q: np.exp(q), np.zeros(1), ["p0"], cov, _shift1, offsets=D)
    assert c.n_draws == 0 and c.low90[0] < 0.0
    # without draws the failing row is clipped at the bound, and says so
    d = P.checked_band(lambda q: np.exp(q), np.zeros(1), ["p0"], cov, _shift1, lower=0.0)
    assert d.method[0] == P.METHOD_CLIPPED and d.low90[0] == 0.0 and d.high90[0] == pytest.approx(1 + P.Z90 * s, rel=1e-2)


def test_checked_band_compares_every_row_with_the_draws_once_they_run():
    cov = np.array([[0.64]])

    def predict(q):
        x = np.asarray(q, float)[0]
        return np.array([np.exp(x), x * x + 5.0, 2.0 * x + 1.0])   # bounded; curved, no bound; linear, no bound

    b = P.checked_band(predict, np.zeros(1), ["p0"], cov, _shift1, lower=[0.0, np.nan, np.nan],
                       offsets=_gauss(cov, 400))
    assert list(b.method) == [P.METHOD_BOUND, P.METHOD_NONLINEAR, P.METHOD_LINEAR]
    # the curved row's linear band has no width at q = 0 (zero gradient); the draws' band is chi-square shaped
    assert b.low90[1] >= 5.0 and b.high90[1] == pytest.approx(5.0 + 0.64 * P.Z90**2, rel=0.2)
    assert b.high90[2] == pytest.approx(1.0 + 2.0 * P.Z90 * 0.8)


def test_checked_band_says_when_too_few_draws_converge():
    cov = np.array([[0.64]])

    def draw(q):
        return np.array([np.nan]) if np.asarray(q)[0] > -1.0 else np.exp(q)   # most draws "do not converge"

    b = P.checked_band(np.exp, np.zeros(1), ["p0"], cov, _shift1, lower=0.0, predict_draw=draw,
                       offsets=_gauss(cov, 64))
    assert b.method[0] == P.METHOD_CLIPPED and b.low90[0] == 0.0 and "64 posterior draws" in b.summary()


def test_sample_posterior_reproduces_a_gaussian_posterior_and_respects_a_one_sided_constraint():
    """The MCMC on r(q) = A q - b recovers the analytic Gaussian posterior (mean, covariance), is seeded; with a steep
    one-sided penalty inactive at the MAP (zero curvature there, so the Laplace spread ignores it), the draws respect
    it and their spread is below the Laplace one: the case the bands need the draws for."""
    A = np.array([[2.0, 0.5], [0.0, 1.0], [1.0, 1.0]])
    b = np.array([1.0, 0.5, 0.2])
    q_map = np.linalg.lstsq(A, b, rcond=None)[0]
    cov = np.linalg.inv(A.T @ A)
    post = P.laplace_posterior(["p0", "p1"], q_map, q_map, np.ones(2), -10 * np.ones(2), 10 * np.ones(2), A,
                               A @ q_map - b, ["r0", "r1", "r2"], 3)
    s = P.sample_posterior(lambda q: A @ q - b, post, walkers=16, steps=1500, burn_in=300, keep=200, seed=3)
    np.testing.assert_allclose(s.chain_sd, np.sqrt(np.diag(cov)), rtol=0.15)
    assert np.all(np.abs(s.draws.mean(axis=0) - q_map) < 0.25 * np.sqrt(np.diag(cov)))
    s2 = P.sample_posterior(lambda q: A @ q - b, post, walkers=16, steps=1500, burn_in=300, keep=200, seed=3)
    np.testing.assert_array_equal(s.draws, s2.draws)
    t = P.sampling_table(post, s)
    assert list(t.columns) == list(P.SAMPLING_COLUMNS) and t["sd_ratio_sampled_over_laplace"].between(0.85, 1.15).all()

    def walled(q):   # p0 may not exceed its MAP by more than 0.05: a steep one-sided penalty, zero at the MAP
        return np.concatenate([A @ q - b, [1e3 * max(0.0, q[0] - q_map[0] - 0.05)]])

    w = P.sample_posterior(walled, post, walkers=16, steps=1500, burn_in=300, keep=200, seed=3)
    assert w.draws[:, 0].max() <= q_map[0] + 0.06
    assert w.chain_sd[0] < 0.8 * np.sqrt(cov[0, 0])
    # control: offsets are the draws minus the MAP
    np.testing.assert_allclose(w.offsets, w.draws - q_map)


def test_report_says_what_the_draws_say_of_the_laplace_spread_and_how_each_band_was_made():
    from lumbar.report.posterior import BAND_METHOD_WORDS, sampling_sentence

    s = pd.DataFrame({"parameter": ["a", "b"], "sd_ratio_sampled_over_laplace": [0.2, 0.9], "walkers": 40,
                      "steps": 250, "burn_in": 100, "independent_samples": 390.0})
    text = sampling_sentence(s)
    assert "40 walkers x 250 steps" in text and "0.2 to 0.9 times the Laplace spread" in text
    assert sampling_sentence(None) == "" and sampling_sentence(s.iloc[:0]) == ""
    # every way a band can be made has words in the report (a new method without words would print its code)
    assert set(BAND_METHOD_WORDS) == {P.METHOD_LINEAR, P.METHOD_BOUND, P.METHOD_NONLINEAR, P.METHOD_CLIPPED}


def test_draw_settings_are_checked_before_any_computation_and_name_the_config_key():
    assert P.check_draw_settings({}, 20) == P.DRAW_DEFAULTS
    for bad, field in (({"burn_in": 300}, "burn_in"), ({"walkers": 30}, "walkers"), ({"keep": 0}, "keep"),
                       ({"walker": 40}, "unknown")):
        with pytest.raises(ValueError, match=f"stepwise_reduction.posterior_draws.*{field}|{field}.*posterior_draws"):
            P.check_draw_settings(bad, 20)
