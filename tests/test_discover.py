"""Discrepancy discovery: candidate effects (lumbar.experiments.effects) and lumbar.discovery.

Datasets with a planted effect are TEST FIXTURES made in the tests (lumbar.discovery.make_hidden_effect_dataset,
or the synthetic L2-S1 / muscle-model tables below), never data.
"""
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lumbar import discovery as D
from lumbar.discovery import power_study
from lumbar.discovery import fit as discovery_fit
from lumbar.experiments import effects as fx
from lumbar.mechanics import so3

ROOT = Path(__file__).resolve().parents[1]
VA_FILE = ROOT / "data" / "experiments" / "heuer2007_va_artefact_original_text.csv"
# a small ROM scenario set: stages where every solver effect acts, two moments
SMALL = {"stages": ["intact", "wo_cl", "wo_va", "wo_pll"], "moments_nm": [2.5, 7.5], "n_specimens": 8,
         "noise_sd_deg": 0.3, "noise_sd_mpa": 0.02, "generator": "batch"}


def config(tmp_path=None, **disc):
    d = {"grid_points": 7, "null_specimens": 0, "benchmark": dict(SMALL)}
    d.update(disc)
    return {"seed": 7, "characteristics": {"data_dir": str(ROOT / "data" / "characteristics")}, "discovery": d}


@pytest.fixture(scope="module")
def fv():
    return D.fsu_variants_from_config(config())


# ------------------------------------------------------------------ fixtures of the L2-S1 and muscle-model schemas
def in_vivo_fixture(tmp_path, k_moment=0.0, seed=0):
    """TEST FIXTURE of the muscle model's output tables (the muscle stage's contract), with an optional hidden moment
    term: results/tables/in_vivo_validation.csv and muscle_model_segment_loads.csv schemas."""
    acts = ["extension_20deg", "relaxed_standing", "crate_close_chest", "crate_far_60cm", "flexion_36deg",
            "lift_round_back", "sitting_max_flexion", "lying_prone"]
    F = np.array([450, 400, 700, 1200, 900, 1500, 600, 120.0])
    M = np.array([-8, 1, 12, 45, 35, 60, 20, 0.0])
    per_n = 0.85 / (18e-4 * 0.66)
    sim = F * per_n / 1e6
    rng = np.random.default_rng(seed)
    meas = sim + k_moment * np.abs(M) / 1e6 + rng.normal(0, 0.03, len(acts))
    val = pd.DataFrame({"activity": acts, "idp_sim_mpa": sim, "idp_in_vivo_mpa": meas,
                        "source": "TEST FIXTURE", "converged": True})
    loads = pd.DataFrame({"level": "L4-L5", "activity": acts, "compressive_n": F, "shear_n": 50.0, "moment_nm": M,
                          "converged": True})
    pv, pl = tmp_path / "in_vivo_validation_fixture.csv", tmp_path / "muscle_model_segment_loads_fixture.csv"
    val.to_csv(pv, index=False)
    loads.to_csv(pl, index=False)
    return pv, pl


# ------------------------------------------------------------------ effects vanish at 0, exact Jacobians
SOLVER = ["ligament_prestrain", "va_neutral_offset", "itl", "passive_muscle", "axial_preload", "disc_tension"]


def _state(m, seed=1):
    rng = np.random.default_rng(seed)
    x, R = m.reference_state(2)
    x = x + rng.normal(0, 3e-4, x.shape)
    x[:, :, 2] -= 5e-4
    return x, so3.exp(rng.normal(0, 0.04, (2, m.nb, 3))) @ R


def test_each_effect_vanishes_at_zero(fv):
    base = fv.fsu.model
    x, R = _state(base)
    stages = ["wo_cl", "wo_va"]
    fb, cb = fv.fsu.masks(stages)
    Q0, J0 = base.evaluate(x, R, None, fb, cb)
    for name in SOLVER:
        fm, cm, params, G = fv.masks_params(stages, {name: np.zeros(1)})
        Q, J = fv.model.evaluate(x, R, None, fm, cm, params=params)
        assert np.array_equal(Q, Q0) and np.array_equal(J, J0), name
    idp = np.array([3e5, 5e5])
    for name in fx.effect_names(kind="idp"):
        assert np.array_equal(fx.idp_delta(name, 0.0, idp, np.array([2.0, -3.0]), 1e3), idp), name


@pytest.mark.parametrize("name", SOLVER)
def test_effect_jacobian_matches_finite_differences(fv, name):
    lo, hi = fx.EFFECTS[name].bounds
    value = fx.EFFECTS[name].magnitudes[-1] if fx.EFFECTS[name].experiments else 0.5 * hi
    stages = ["wo_cl", "wo_va"]
    fm, cm, params, _ = fv.masks_params(stages, {name: np.full(1, value)})
    m = fv.model
    x, R = _state(m)
    loads = np.random.default_rng(2).normal(0, 1, (2, m.nb, 6))
    Q, J = m.evaluate(x, R, loads, fm, cm, params=params)
    h = 1e-7
    Jfd = np.zeros_like(J)
    for k in range(6):
        d = np.zeros((2, m.nb, 6))
        d[:, 0, k] = h
        Qp, _ = m.evaluate(x + d[..., :3], so3.exp(d[..., 3:]) @ R, loads, fm, cm, jacobian=False, params=params)
        Qm, _ = m.evaluate(x - d[..., :3], so3.exp(-d[..., 3:]) @ R, loads, fm, cm, jacobian=False, params=params)
        Jfd[:, :, :, 0, k] = (Qp - Qm) / (2 * h)
    assert np.abs(J - Jfd).max() < 1e-6 * np.abs(J).max() + 1e-3, name


def test_generator_switches_an_effect_on():
    """lumbar.experiments.virtual_experiment.stepwise_reduction_table(effects=...) makes data with a hidden effect."""
    from lumbar.inputs.characteristics import load_characteristic_set
    from lumbar.geometry import load_geometry
    from lumbar.experiments.virtual_experiment import stepwise_reduction_table
    geo = load_geometry("default", levels=["L4-L5"])
    cs = load_characteristic_set("calibrated")
    kw = dict(n_specimens=1, noise_sd_deg=0.0, moments_nm=(5.0,))
    a = stepwise_reduction_table(geo, cs, 3, **kw)
    b = stepwise_reduction_table(geo, cs, 3, effects={"passive_muscle": 20.0}, **kw)
    d = (b["rom_mean_deg"] - a["rom_mean_deg"]).abs()
    arch = a["stage"].isin(fx.ARCH_STAGES)
    assert d[~arch].max() > 0.2 and d[arch].max() < 1e-6
    assert "passive_muscle" in b["source"].iat[0]


def test_idp_generator_rejects_an_effect_without_idp_form():
    from lumbar.experiments.virtual_experiment import idp_table
    with pytest.raises(ValueError, match="effect 'itl' does not act on the IDP from the disc loads"):
        idp_table(None, None, 1, effects={"itl": 0.1})


# ------------------------------------------------------------------ discovery: planted effects and nulls
def test_planted_rom_effect_is_named_with_parameter_within_20pct_and_gap_shrinks():
    cfg = config()
    true = 0.03
    df = D.make_hidden_effect_dataset(cfg, "stepwise_rom", "ligament_prestrain", true, seed=11)
    assert "TEST FIXTURE" in df["source"].iat[0]
    out = D.discover(D.build_problem("stepwise_rom", df, cfg), D.discovery_settings(cfg))
    r = out["result"]
    assert r["named_effect"] == "ligament_prestrain"
    assert abs(r["parameter_estimate"]["value"] - true) <= 0.2 * true
    assert r["gap_after"] < 0.5 * r["gap_before"]
    assert r["forward_batches"] == 2          # the coarse grid of every candidate; the best one's exact refit
    assert r["ranking"][0][0] == "ligament_prestrain" and r["confidence"] > 0.9
    assert r["p_value"] < 0.01 and r["null_distribution_size"] == D.default_settings()["n_bootstrap"]
    assert r["at_bound"]["ligament_prestrain"] is False and r["parameter_estimate"]["at_bound"] is False


def test_rom_null_is_not_named():
    cfg = config()
    df = D.make_hidden_effect_dataset(cfg, "stepwise_rom", "none", 0.0, seed=12)
    r = D.discover(D.build_problem("stepwise_rom", df, cfg), D.discovery_settings(cfg))["result"]
    assert r["named_effect"] is None and r["parameter_estimate"] is None
    assert r["gap_after"] == r["gap_before"]
    assert r["decision"].startswith("nothing named")
    assert r["confidence"] is None           # no "confidence" of an effect that is not named
    assert r["p_value"] > 0.01


@pytest.mark.parametrize("name", ["axial_preload", "idp_moment_term", "disc_load_share"])
def test_planted_idp_effect_is_named(idp_model_fixture, name):
    cfg = config()
    true = fx.EFFECTS[name].magnitudes[0]
    df = D.make_hidden_effect_dataset(cfg, "idp_invitro", name, true, seed=5, idp_model=idp_model_fixture)
    r = D.discover(D.build_problem("idp_invitro", df, cfg, idp_model=idp_model_fixture),
                   D.discovery_settings(cfg))["result"]
    assert r["named_effect"] == name
    assert abs(r["parameter_estimate"]["value"] - true) <= 0.2 * true
    assert r["gap_after"] < 0.3 * r["gap_before"]


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_idp_nulls_are_not_named(idp_model_fixture, seed):
    cfg = config()
    df = D.make_hidden_effect_dataset(cfg, "idp_invitro", "none", 0.0, seed=seed, idp_model=idp_model_fixture)
    r = D.discover(D.build_problem("idp_invitro", df, cfg, idp_model=idp_model_fixture),
                   D.discovery_settings(cfg))["result"]
    assert r["named_effect"] is None


@pytest.mark.parametrize("seed", range(30, 50))
def test_idp_null_p_values_are_not_small(idp_model_fixture, seed):
    """Twenty IDP null fixtures: nothing named, and the bootstrap p-value is a p-value (not ~0 on nulls as the
    QAICc margin was): the median over the nulls is checked in the next test."""
    cfg = config()
    df = D.make_hidden_effect_dataset(cfg, "idp_invitro", "none", 0.0, seed=seed, idp_model=idp_model_fixture)
    r = D.discover(D.build_problem("idp_invitro", df, cfg, idp_model=idp_model_fixture),
                   D.discovery_settings(cfg))["result"]
    assert r["named_effect"] is None and r["confidence"] is None
    assert_bootstrap_p_value(r)


def assert_bootstrap_p_value(r):
    """The reported p-value is the max-T bootstrap count (1 + #{T_null >= T_obs}) / (1 + B), checked against what the
    result returns beside it: a count k in 0..B; on the side of each returned null quantile that the observed
    statistic (the largest LR statistic over the candidates) falls on; at least the unadjusted p of the candidate."""
    B, p = r["null_distribution_size"], r["p_value"]
    assert B == D.default_settings()["n_bootstrap"] and B > 0
    k = p * (B + 1) - 1
    assert abs(k - round(k)) < 1e-6 and 0 <= round(k) <= B, (p, B)
    T = max(r["lr_statistic"].values())
    for q, t_q in r["null_lr_quantiles"].items():
        tail = 1 - float(q)
        if T < t_q:      # at least the share 1 - q of the null tables reach T
            assert p >= tail * B / (B + 1), (p, q, T, t_q)
        elif T > t_q:    # at most that share (and the quantile's own table) reach it
            assert p <= (tail * B + 2) / (B + 1), (p, q, T, t_q)
    best = max(r["lr_statistic"], key=r["lr_statistic"].get)
    assert r["p_values_unadjusted"][best] <= p + 1e-12


def test_idp_null_p_values_spread_like_a_uniform(idp_model_fixture):
    cfg = config()
    ps = []
    for seed in range(60, 90):
        df = D.make_hidden_effect_dataset(cfg, "idp_invitro", "none", 0.0, seed=seed, idp_model=idp_model_fixture)
        ps.append(D.discover(D.build_problem("idp_invitro", df, cfg, idp_model=idp_model_fixture),
                             D.discovery_settings(cfg))["result"]["p_value"])
    ps = np.array(ps)
    assert (ps < 0.01).sum() <= 1 and 0.2 < np.median(ps) < 0.8, ps


def test_estimate_on_its_bound_is_flagged_and_the_effect_not_named(idp_model_fixture):
    """A preload beyond the fit bound (1000 N): the estimate sits on the bound, the refit leaves a misfit the null
    tables do not have, so the effect is not named; the uniform offset it is equivalent to on this experiment
    explains the table and is reported as the nuisance."""
    cfg = config()
    df = D.make_hidden_effect_dataset(cfg, "idp_invitro", "axial_preload", 1500.0, seed=5, idp_model=idp_model_fixture)
    r = D.discover(D.build_problem("idp_invitro", df, cfg, idp_model=idp_model_fixture),
                   D.discovery_settings(cfg))["result"]
    assert r["named_effect"] is None and r["best_candidate"] == "axial_preload"
    assert r["at_bound"]["axial_preload"] is True and r["adequacy_p"]["best_candidate"] < r["alpha"]
    assert r["decision"].startswith("nuisance: uniform offset +")
    assert "axial_preload" in r["nuisance"]["uniform offset"]["equivalent_candidates"]
    assert "uniform offset" in r["nuisance_test"]["equivalent_nuisance"]
    assert r["gap_after"] == r["gap_before"] and r["gap_nuisance"] < 1.5 < r["gap_before"]


def test_identifiability_flags_a_collinear_pair_with_load_cases_from_the_design_space(idp_model_fixture):
    cfg = config(max_correlation=0.3, n_next=4)
    sub = idp_model_fixture[idp_model_fixture["load_case"].isin(["neutral", "flexion"])]
    df = D.make_hidden_effect_dataset(cfg, "idp_invitro", "none", 0.0, seed=3, idp_model=idp_model_fixture)
    df = df.merge(sub[["muscle_setup", "load_case"]])
    r = D.discover(D.build_problem("idp_invitro", df, cfg, idp_model=idp_model_fixture),
                   D.discovery_settings(cfg))["result"]
    ident = r["identifiability"]
    assert set(ident["correlation"]) == {"axial_preload | idp_moment_term", "axial_preload | disc_load_share",
                                         "idp_moment_term | disc_load_share"}
    assert all(-1 - 1e-9 <= v <= 1 + 1e-9 for v in ident["correlation"].values())
    assert ident["non_separable"], ident
    design = set(zip(idp_model_fixture["muscle_setup"], idp_model_fixture["load_case"]))
    for item in ident["non_separable"]:
        assert abs(item["correlation"]) >= 0.3
        nxt = item["measure_next"]
        assert len(nxt) == 4 and all((m["muscle_setup"], m["load_case"]) in design for m in nxt)
        sep = [m["separation_z"] for m in nxt]
        assert sep == sorted(sep, reverse=True) and sep[0] > 0
    # with the default threshold the same experiment separates these candidates
    r2 = D.discover(D.build_problem("idp_invitro", df, config(), idp_model=idp_model_fixture),
                    D.discovery_settings(config()))["result"]
    flagged = {tuple(i["pair"]) for i in r2["identifiability"]["non_separable"]}
    assert all(abs(r2["identifiability"]["correlation"][" | ".join(p)]) >= 0.9 for p in flagged)


def test_bootstrap_resampler_reproduces_the_generator_spread(idp_model_fixture):
    """The parametric bootstrap's null tables have the spread of the fixture generator's (same noise model)."""
    cfg = config()
    df = D.make_hidden_effect_dataset(cfg, "idp_invitro", "none", 0.0, seed=1, idp_model=idp_model_fixture)
    prob = D.build_problem("idp_invitro", df, cfg, idp_model=idp_model_fixture)
    center = prob.forward({})[0]
    Y, S = discovery_fit._resample(prob, center, 1.0, 400, np.random.default_rng(0))
    sd_gen = SMALL["noise_sd_mpa"] / np.sqrt(SMALL["n_specimens"])
    assert abs(np.std(Y - center) / sd_gen - 1) < 0.1
    gen = np.concatenate([D.build_problem("idp_invitro", D.make_hidden_effect_dataset(
        cfg, "idp_invitro", "none", 0.0, seed=k, idp_model=idp_model_fixture), cfg, idp_model=idp_model_fixture).sigma
        for k in range(40)])
    assert abs(np.median(S) / np.median(gen) - 1) < 0.05 and abs(np.mean(S) / np.mean(gen) - 1) < 0.05


def test_benchmark_cases_seeds_magnitudes_and_nulls():
    cfg = config()
    cfg["discovery"]["benchmark"] = dict(SMALL, effects=["itl", "axial_preload"], n_magnitudes=2, n_seeds=3,
                                         near_threshold_factors=[0.25], n_null=5)
    c = D.benchmark_cases(cfg)
    assert (c["hidden_effect"] == "none").sum() == 5
    g = c[c["hidden_effect"] != "none"].groupby(["hidden_effect", "magnitude"]).size()
    assert (g == 3).all() and len(g) == 6
    assert np.isclose(c.loc[c["magnitude_label"] == "near0.25", "magnitude"].min(),
                      0.25 * min(fx.EFFECTS["itl"].magnitudes))
    assert c["seed"].is_unique and c["case"].is_unique


def test_benchmark_summary_false_positive_rate_interval_and_power():
    bench = pd.DataFrame({"case": list("abcdefghi"), "experiment": "stepwise_rom",
                          "category": ["library"] * 4 + ["no_effect"] * 2 + ["out_of_library"] * 3,
                          "hidden_effect": ["itl", "itl", "itl", "itl", "none", "none", "disc_scale", "disc_scale",
                                            "disc_scale"],
                          "magnitude_label": ["near0.25", "near0.25", "m1", "m1", "none", "none", "x0.7", "x0.7",
                                              "x1.3"],
                          "magnitude": [0.025, 0.025, 0.1, 0.1, 0.0, 0.0, 0.7, 0.7, 1.3],
                          "named_effect": ["itl", "none", "itl", "itl", "none", "itl", "none", "itl", "none"],
                          "correct": [True, False, True, True, True, False, True, False, True],
                          "decision": ["named: itl", "nothing named", "named: itl", "named: itl", "nothing named",
                                       "named: itl", "unexplained", "named: itl", "nuisance: uniform scale 0.9"],
                          "p_value": [0.005, 0.3, 0.005, 0.005, 0.5, 0.005, 0.2, 0.005, 0.1],
                          "param_true": [0.025, 0.025, 0.1, 0.1, np.nan, np.nan, np.nan, np.nan, np.nan],
                          "param_est": [0.03, np.nan, 0.08, 0.12, np.nan, np.nan, np.nan, np.nan, np.nan],
                          "gap_before": 2.0, "gap_after": 1.0})
    s = D.summarise_benchmark(bench)
    assert s["n_null"] == 2 and s["false_positives"] == 1 and s["false_positive_rate"] == 0.5
    lo, hi = s["false_positive_rate_95ci"]
    assert 0 < lo < 0.5 < hi < 1
    pw = {p["magnitude"]: p for p in s["power"]}
    assert pw[0.025]["power"] == 0.5 and pw[0.1]["power"] == 1.0 and pw[0.1]["relative_magnitude"] == 1.0
    assert np.isclose(pw[0.1]["median_param_rel_error"], 0.2)
    assert s["library_at_benchmark_magnitudes"]["n"] == 2 and s["library_at_benchmark_magnitudes"]["rate"] == 1.0
    assert s["out_of_library_unnamed"]["k"] == 2 and s["out_of_library_unnamed"]["n"] == 3
    assert s["out_of_library_named"] == {"itl": 1}
    assert s["decisions"]["out_of_library"] == {"named": 1, "nuisance": 1, "unexplained": 1}
    assert s["pass"]["false_positive_rate_max"] is False and s["pass"]["library_named_at_benchmark_magnitudes_min"]
    assert s["pass"]["out_of_library_unnamed_min"] is False and s["all_pass"] is False
    assert power_study._interval(0, 50)[0] == 0 and 0.05 < power_study._interval(0, 50)[1] < 0.08
    text = D.benchmark_paragraph(s)       # the candidates without fixtures are named in the report, with the reason
    assert "Not benchmarked: " in text and "lumbosacral_disc_height (acts only on multilevel_rom" in text


def test_benchmark_names_the_candidates_it_cannot_test_and_why():
    """A candidate acting only on an experiment without fixtures (the lumbosacral disc: multilevel ROM) is listed as
    not benchmarked, with its experiment; a candidate on a benchmarked experiment is not (control)."""
    nb = power_study.not_benchmarked({"stepwise_rom", "idp_invitro"})
    assert "multilevel_rom" in nb["lumbosacral_disc_height"] and "disc_tension" in nb
    assert "itl" not in nb and "axial_preload" not in nb
    assert "lumbosacral_disc_height" not in power_study.not_benchmarked({"stepwise_rom", "multilevel_rom"})
    assert set(power_study.not_benchmarked(set())) == {n for n, e in fx.EFFECTS.items()}


def test_virtual_specimens_without_equilibrium_are_redrawn_not_dropped():
    """Survivor bias: a specimen that fails a scenario is replaced as a whole by a seeded reserve
    specimen; a scenario most specimens fail is a model limit and reported as such."""
    import logging
    from lumbar.experiments.virtual_experiment import _without_survivor_bias
    sim = pd.DataFrame({"stage": ["intact"] * 3, "direction": ["flexion"] * 3, "moment_nm": [1.0, 5.0, 10.0]})

    def one(rng):
        u = rng.random()
        conv = np.array([True, u > 0.3, False])        # scenario 3 never converges: a model limit
        return sim, np.array([1.0, 2.0 + u, 3.0]), conv

    log = logging.getLogger("test")
    a = _without_survivor_bias(one, 5, 8, log)
    b = _without_survivor_bias(one, 5, 8, log)
    _, vals, redrawn, limit = a
    assert redrawn > 0 and list(limit) == [False, False, True]
    V = np.vstack(vals)
    assert np.isfinite(V[:, :2]).all()                # every specimen in every non-limit row
    assert np.array_equal(V, np.vstack(b[1]), equal_nan=True) and b[2] == redrawn
    # the survivors of row 2 alone would be biased upwards (u > 0.3); the re-drawn specimens are the same
    # population, so the row is averaged over complete specimens only
    assert (V[:, 1] > 2.3).all()


def test_virtual_specimens_without_a_model_are_redrawn_and_do_not_make_limits():
    """A specimen whose drawn prestrain puts a law outside its domain on its short fibres has no model
    (simulate_one returns None): it is replaced by a reserve specimen like one without equilibrium, and its missing
    rows are not counted towards a model limit (half the first specimens without a model would otherwise mark every
    scenario a limit). Control: when no specimen has a model the table is refused by name."""
    import logging
    from lumbar.experiments.fsu import LawDomainError
    from lumbar.experiments.virtual_experiment import _without_survivor_bias
    sim = pd.DataFrame({"stage": ["intact"] * 2, "direction": ["flexion"] * 2, "moment_nm": [1.0, 10.0]})

    def one(rng):
        u = rng.random()
        return (None, None, None) if u < 0.5 else (sim, np.array([1.0, 2.0 + u]), np.array([True, True]))

    _, vals, redrawn, limit = _without_survivor_bias(one, 3, 8, logging.getLogger("test"))
    assert redrawn > 0 and not limit.any()
    V = np.vstack(vals)
    assert np.isfinite(V).all() and (V[:, 1] >= 2.5).all()      # every row from specimens with a model
    with pytest.raises(LawDomainError, match="none of the first 4 virtual specimens has a model"):
        _without_survivor_bias(lambda rng: (None, None, None), 3, 4, logging.getLogger("test"))


# ------------------------------------------------------------------ CLI, published artefact, in vivo
def test_cli_va_artefact_has_too_few_rows_and_names_nothing(tmp_path, capsys):
    """The published artefact is one difference (0.66 -> 2.2 deg): too few rows to name anything."""
    out = tmp_path / "va"
    rc = D.main(["--config", str(ROOT / "config" / "test" / "config.yaml"), "--measured", str(VA_FILE),
                 "--out", str(out)])
    assert rc == 0
    r = json.loads((out / "discovery.json").read_text())
    for k in ("named_effect", "parameter_estimate", "gap_before", "gap_after", "ranking", "confidence", "p_value",
              "null_distribution_size", "at_bound", "gap_after_above_threshold", "identifiability"):
        assert k in r
    assert r["experiment"] == "neutral_angle" and r["n_scenarios"] == 1
    assert r["named_effect"] is None and r["confidence"] is None and r["p_value"] is None
    assert r["too_few_rows"] is True and "too few rows: 1 scenario(s)" in r["decision"]
    for f in ("disagreement_map.png", "ranking.png", "before_after.png", "section.md", "scenarios.csv"):
        assert (out / f).stat().st_size > 100, f
    printed = json.loads(capsys.readouterr().out)
    assert printed["named_effect"] is None and printed["confidence"] is None


def test_real_data_summary_table(tmp_path):
    pv, pl = in_vivo_fixture(tmp_path, k_moment=0.02e6)
    cfg = config(in_vivo_segment_loads=str(pl))
    D.run(cfg, pv, tmp_path / "in_vivo")
    D.run(config(), VA_FILE, tmp_path / "va_artefact")
    t = D.real_data_summary([tmp_path / "in_vivo" / "discovery.json", tmp_path / "va_artefact" / "discovery.json"])
    assert list(t.columns) == list(D.REAL_DATA_COLUMNS)
    assert list(t["dataset"]) == ["in_vivo", "va_artefact"] and list(t["n_rows"]) == [8, 1]
    assert t["named_effect"].iat[0] == "idp_moment_term" and t["estimate"].iat[0].endswith("Pa/(N*m)")
    assert t["named_effect"].iat[1] == "" and "too few rows" in t["note"].iat[1]


def test_in_vivo_planted_moment_term_is_named_and_null_is_not(tmp_path):
    pv, pl = in_vivo_fixture(tmp_path, k_moment=0.02e6)
    cfg = config(in_vivo_segment_loads=str(pl))
    r = D.run(cfg, pv, tmp_path / "out")
    assert r["named_effect"] == "idp_moment_term"
    assert abs(r["parameter_estimate"]["value"] - 0.02e6) <= 0.2 * 0.02e6
    pv0, _ = in_vivo_fixture(tmp_path, k_moment=0.0, seed=1)
    assert D.run(cfg, pv0, tmp_path / "out0")["named_effect"] is None


# ------------------------------------------------------------------ bad input: clear messages before any solve
def test_reject_missing_measured_file(tmp_path):
    with pytest.raises(D.DiscoveryInputError, match=r"^measured file not found: .*nope\.csv$"):
        D.read_measured(tmp_path / "nope.csv")


def test_reject_table_of_unknown_schema(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("a,b\n1,2\n")
    with pytest.raises(D.DiscoveryInputError) as e:
        D.read_measured(p)
    assert str(e.value) == (f"{p}: columns ['a', 'b'] match no experiment schema; expected one of "
                            "stepwise_rom: ['stage', 'direction', 'moment_nm', 'rom_mean_deg', 'rom_min_deg', "
                            "'rom_max_deg', 'n_specimens']; idp_invitro: ['muscle_setup', 'load_case', 'idp_mean_mpa', "
                            "'idp_sd_mpa', 'n_specimens']; in_vivo: ['activity', 'idp_sim_mpa', 'idp_in_vivo_mpa', "
                            "'converged']; neutral_angle: ['stage', 'lordosis_deg']")


def test_reject_rom_table_missing_a_column(tmp_path):
    p = tmp_path / "rom.csv"
    p.write_text("stage,direction,moment_nm,rom_mean_deg,n_specimens\nintact,flexion,5,3,8\n")
    with pytest.raises(D.DiscoveryInputError) as e:
        D.read_measured(p)
    assert str(e.value) == (f"{p}: looks like a stepwise_rom table but column(s) ['rom_min_deg', 'rom_max_deg'] are "
                            "missing; expected columns ['stage', 'direction', 'moment_nm', 'rom_mean_deg', "
                            "'rom_min_deg', 'rom_max_deg', 'n_specimens']")


def test_reject_malformed_value_in_in_vivo_table(tmp_path):
    p = tmp_path / "iv.csv"
    p.write_text("activity,idp_sim_mpa,idp_in_vivo_mpa,source,converged\nstanding,0.5,abc,x,True\n")
    with pytest.raises(D.DiscoveryInputError) as e:
        D.read_measured(p)
    assert str(e.value) == (f"{p}, row 1, column 'idp_in_vivo_mpa': got 'abc', which is not a number; expected a "
                            "finite number >= 0 (in-vivo IDP [MPa])")


IV_HEAD = "activity,idp_sim_mpa,idp_in_vivo_mpa,source,converged\n"
NA_HEAD = "stage,lordosis_deg,lordosis_sd_deg\n"


@pytest.mark.parametrize("text, expected", [
    (IV_HEAD + "standing,0.5,0.5,x,yes\n",
     "row 1, column 'converged': got 'yes'; expected one of 'False', 'True', 'false', 'true' (not empty)"),
    (IV_HEAD + "standing,inf,0.5,x,True\n",
     "row 1, column 'idp_sim_mpa': got non-finite value 'inf'; expected a finite number >= 0 (or empty)"),
    (IV_HEAD + "standing,,0.5,x,True\n",
     "row 1, column 'idp_sim_mpa': empty on a converged row; expected a finite number >= 0"),
    (IV_HEAD + "standing,0.5,0.5,x,True\nsitting,0.4,0.5,x\n",
     "row 2, column 'converged': 4 field(s) but the header has 5; expected one value per header column"),
    (NA_HEAD + "wo_cl,0.66,\nwo_va,2.2,0\n",
     "row 2, column 'lordosis_sd_deg': got 0, a zero uncertainty; expected a finite number > 0 [deg]"),
    (NA_HEAD + "wo_cl,abc,\nwo_va,2.2,\n",
     "row 1, column 'lordosis_deg': got 'abc', which is not a number; expected a finite number in [-90, 90]"),
    (NA_HEAD + "wo_cl,0.66,\nwo_va,inf,\n",
     "row 2, column 'lordosis_deg': got non-finite value 'inf'; expected a finite number in [-90, 90]"),
    (NA_HEAD + "wo_cl,0.66,,1\nwo_va,2.2,\n",
     "row 1: 4 field(s) but the header has 3; expected one value per header column"),
])
def test_neutral_angle_and_in_vivo_tables_go_through_a_schema(tmp_path, text, expected):
    """bad cells name the file, the 1-based data row, the column and the expected form."""
    p = tmp_path / "t.csv"
    p.write_text(text)
    with pytest.raises(D.DiscoveryInputError) as e:
        D.read_measured(p)
    assert str(e.value).startswith(f"{p}, {expected}"), str(e.value)


def test_reject_invalid_stage_in_neutral_angle_table(tmp_path):
    p = tmp_path / "na.csv"
    p.write_text("stage,lordosis_deg\nwo_cl,0.66\nwo_arch,2.2\n")
    with pytest.raises(D.DiscoveryInputError) as e:
        D.read_measured(p)
    assert str(e.value).startswith(f"{p}, row 2, column 'stage': got 'wo_arch'; expected one of 'intact', 'wo_all', ")


def test_reject_rom_table_with_bad_value_names_row_and_column(tmp_path):
    p = tmp_path / "rom.csv"
    p.write_text("stage,direction,moment_nm,rom_mean_deg,rom_min_deg,rom_max_deg,n_specimens,kind,source\n"
                 "intact,flexion,5,3,4,5,8,surrogate,x\n")
    with pytest.raises(D.DiscoveryInputError, match="rom_mean_deg 3 is not within"):
        D.read_measured(p)


def test_reject_missing_segment_loads_for_in_vivo(tmp_path):
    pv, _ = in_vivo_fixture(tmp_path)
    cfg = config(in_vivo_segment_loads=str(tmp_path / "missing.csv"))
    with pytest.raises(D.DiscoveryInputError) as e:
        D.run(cfg, pv, tmp_path / "o")
    assert str(e.value) == (f"segment-load table not found: {tmp_path / 'missing.csv'} (config "
                            "discovery.in_vivo_segment_loads); the in-vivo discovery needs the muscle model's segment "
                            "loads with columns ['level', 'activity', 'compressive_n', 'shear_n', 'moment_nm', "
                            "'converged']")
    assert not (tmp_path / "o").exists()


def test_reject_unknown_or_out_of_bounds_effect():
    with pytest.raises(ValueError, match=r"^unknown effect 'gravity'; known effects: \["):
        fx.check_effect("gravity")
    with pytest.raises(ValueError) as e:
        fx.check_effect("itl", 5.0)
    assert str(e.value) == "effect itl: itl_force_scale = 5.0 1 is outside its bounds [0, 1]"


def test_cli_bad_input_exits_2_with_message(tmp_path, capsys):
    rc = D.main(["--config", str(ROOT / "config" / "test" / "config.yaml"), "--measured",
                 str(tmp_path / "none.csv"), "--out", str(tmp_path / "o")])
    assert rc == 2
    assert capsys.readouterr().err.strip() == f"error: measured file not found: {tmp_path / 'none.csv'}"


def test_idp_surrogate_redraws_a_specimen_without_a_model(monkeypatch):
    """The in-vitro IDP surrogate: a virtual specimen whose drawn law has no model on its fibres is replaced by a
    seeded reserve specimen, the others keep their own streams; control: with every draw outside the domain the
    table is refused by name after the reserve."""
    from lumbar.experiments import virtual_experiment as ve
    from lumbar.experiments.fsu import LawDomainError
    sim = pd.DataFrame({"muscle_setup": ["a", "b"], "load_case": ["x", "x"], "converged": [True, True],
                        "idp_mpa": [0.5, 0.6], "disc_moment_sagittal_nm": [0.0, 0.0]})
    calls = []

    def run_set(geo, cs, cables, **kw):
        calls.append(cs)
        if len(calls) == 2:                       # the second specimen drawn has no model
            raise LawDomainError("test: pre-elongation beyond the shortest fibre")
        return sim.copy(), None

    monkeypatch.setattr(ve, "run_set", run_set)
    monkeypatch.setattr(ve, "virtual_specimen", lambda g, c, rng, v, levels=None: (g, rng.random()))
    geo = type("G", (), {"name": "g", "levels": {"L4-L5": type("L", (), {"disc_csa": 1.6e-3})()}})()
    cs = type("C", (), {"name": "c"})()
    t = ve.idp_table(geo, cs, seed=3, n_specimens=3, cables=object(), noise_sd_mpa=0.0)
    assert len(calls) == 4 and list(t["n_specimens"]) == [3, 3]
    # slots 0 and 2 keep their own streams; slot 1's has no model and is replaced by the first reserve stream (3)
    want = [ve.specimen_rngs(3, 9)[i].random() for i in (0, 1, 3, 2)]
    assert calls == want
    monkeypatch.setattr(ve, "run_set", lambda *a, **k: (_ for _ in ()).throw(LawDomainError("always")))
    with pytest.raises(LawDomainError, match="no model after the reserve of 6 specimens"):
        ve.idp_table(geo, cs, seed=3, n_specimens=3, cables=object(), noise_sd_mpa=0.0)
