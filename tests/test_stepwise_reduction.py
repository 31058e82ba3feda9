"""Forward stepwise reduction (lumbar.experiments.stepwise_reduction): reference tables, derived disc-only rows,
outlier rule, Table 4 on the default surrogate, and the workflow rules on config/test."""

import numpy as np
import pandas as pd
import pytest

from lumbar.experiments import stepwise_reduction as sr
from lumbar.experiments.calibration import derived_disc_only_rows
from lumbar.inputs.characteristics import load_characteristic_set
from lumbar.inputs.io import TableError

from conftest import ROOT

DERIVED = ROOT / "data" / "experiments" / "heuer2007_disc_only_derived_from_published_fit.csv"
EXPECTED = {"flexion": (4.93, 6.60, 8.43, 10.11, 13.41), "extension": (2.25, 4.93, 7.95, 10.29, 12.82),
            "lateral_bending": (2.17, 3.68, 5.19, 6.51, 9.09), "axial_rotation": (1.29, 2.78, 4.45, 5.82, 7.73)}


def test_derived_disc_only_rows_recomputed():
    stored = sr.read_experiment_table(DERIVED)
    again = derived_disc_only_rows(load_characteristic_set("calibrated").disc.torque)
    assert len(stored) == 20 and set(stored["kind"]) == {"derived_from_published_fit"}
    assert stored["rom_min_deg"].isna().all() and stored["rom_max_deg"].isna().all()
    assert stored["source"].str.contains("Table 1").all()
    for d, vals in EXPECTED.items():
        s = stored[stored["direction"] == d].sort_values("moment_nm")["rom_mean_deg"].to_numpy()
        a = again[again["direction"] == d].sort_values("moment_nm")["rom_mean_deg"].to_numpy()
        np.testing.assert_allclose(s, vals, atol=0.01, err_msg=d)
        np.testing.assert_allclose(a, s, atol=1e-4, err_msg=d)


def _table(tmp_path, mutate=None, drop=None):
    df = pd.read_csv(DERIVED)
    if drop:
        df = df.drop(columns=[drop])
    if mutate:
        mutate(df)
    p = tmp_path / "measured.csv"
    df.to_csv(p, index=False)
    return p


def test_reject_measured_table_missing_column(tmp_path):
    p = _table(tmp_path, drop="rom_mean_deg")
    with pytest.raises(TableError, match="rom_mean_deg") as e:
        sr.read_experiment_table(p)
    assert "measured.csv" in str(e.value)


def test_reject_unknown_stage(tmp_path):
    p = _table(tmp_path, lambda d: d.__setitem__("stage", ["wo_nuc"] + list(d["stage"][1:])))
    with pytest.raises(TableError, match=r"measured.csv, row 1, column 'stage'"):
        sr.read_experiment_table(p)


def test_reject_negative_rom(tmp_path):
    p = _table(tmp_path, lambda d: d.__setitem__("rom_mean_deg", [-1.0] + list(d["rom_mean_deg"][1:])))
    with pytest.raises(TableError, match=r"row 1, column 'rom_mean_deg'"):
        sr.read_experiment_table(p)


def test_reject_zero_specimens_row(tmp_path):
    p = _table(tmp_path, lambda d: d.__setitem__("n_specimens", [0] + list(d["n_specimens"][1:])))
    with pytest.raises(TableError, match=r"row 1, column 'n_specimens'"):
        sr.read_experiment_table(p)


def test_malformed_range_mean_outside(tmp_path):
    def m(d):
        d["rom_min_deg"] = d["rom_mean_deg"] + 1.0
        d["rom_max_deg"] = d["rom_mean_deg"] + 2.0
    with pytest.raises(TableError, match="rom_mean_deg.*within"):
        sr.read_experiment_table(_table(tmp_path, m))


def test_bad_duplicate_scenario(tmp_path):
    def m(d):
        d.loc[1, "moment_nm"] = d.loc[0, "moment_nm"]
    with pytest.raises(TableError, match="duplicate"):
        sr.read_experiment_table(_table(tmp_path, m))


def test_outlier_rule_ranges_tolerance_and_non_converged():
    ref = pd.DataFrame({"stage": ["intact", "intact", "wo_all", "wo_all"], "direction": ["flexion"] * 4,
                        "moment_nm": [1.0, 2.5, 1.0, 2.5], "rom_mean_deg": [1.0, 2.0, 5.0, 6.0],
                        "rom_min_deg": [0.5, 1.5, np.nan, np.nan], "rom_max_deg": [1.5, 2.5, np.nan, np.nan],
                        "kind": ["surrogate", "surrogate", "derived_from_published_fit", "derived_from_published_fit"]})
    sim = ref[["stage", "direction", "moment_nm"]].assign(rom_deg=[1.4, np.nan, 5.4, 6.6],
                                                         converged=[True, False, True, True])
    out = sr.assess(sim, ref, "x", tolerance_deg=0.5)
    assert list(out["outlier"]) == [False, True, False, True]
    assert list(out["data_kind"]) == list(ref["kind"])
    counts = sr.outlier_counts(out)
    assert counts.loc[0, "n_outliers"] == 2 and counts.loc[0, "n_not_converged"] == 1


def test_compare_with_paper_missing_file_leaves_column_empty(tmp_path, caplog):
    counts = pd.DataFrame({"set": ["calibrated"], "n_scenarios": [160], "n_outliers": [3]})
    out = sr.compare_with_paper(counts, tmp_path / "absent.csv")
    assert out["paper_n_outliers"].isna().all()
    assert "not found" in caplog.text


def test_reference_table_replaces_surrogate_disc_only_rows():
    der = sr.read_experiment_table(DERIVED)
    sur = der.assign(kind="surrogate", rom_mean_deg=der["rom_mean_deg"] + 1, rom_min_deg=0.0, rom_max_deg=50.0)
    sur = pd.concat([sur, sur.assign(stage="intact")], ignore_index=True)
    ref = sr.reference_table(sur, der)
    assert len(ref) == 40
    assert set(ref.loc[ref["stage"] == "wo_all", "kind"]) == {"derived_from_published_fit"}
    measured = sur.assign(kind="measured")
    assert set(sr.reference_table(measured, der)["kind"]) == {"measured"}


def test_workflow_stepwise_reduction_rules_run(dag_workdir):
    """Surrogate -> calibrate -> forward -> Table 4 + figures on config/test, from the session's DAG run."""
    tmp_path = dag_workdir
    targets = ["results/tables/table4_vs_paper.csv", "results/figures/fig6_rom_stepwise_reduction.png",
               "results/figures/fig4_disc_torque_angle.png", "results/figures/fig5_ligament_characteristics.png"]
    for t in targets:
        assert (tmp_path / t).stat().st_size > 0
    syn = pd.read_csv(tmp_path / "results/tables/table4_rom_synopsis.csv")
    import yaml
    moments = yaml.safe_load((tmp_path / "config/test/config.yaml").read_text())["stepwise_reduction"]["moments_nm"]
    n_scenarios = 8 * 4 * len(moments)                  # stages x directions x moments
    assert set(syn["set"]) == {"calibrated", "rupp2015"} and (syn.groupby("set").size() == n_scenarios).all()
    assert {"surrogate", "derived_from_published_fit"} <= set(syn["data_kind"])
    assert set(syn["data_kind"]) <= {"surrogate", "derived_from_published_fit", "original_text"}   # + real rows
    vs = pd.read_csv(tmp_path / "results/tables/table4_vs_paper.csv")
    assert vs["paper_n_outliers"].isna().all()          # ../shared is not beside the copy: column empty, logged
    assert "not found" in (tmp_path / "logs" / "table4.log").read_text()
    sur = pd.read_csv(tmp_path / "results/experiments/stepwise_reduction_surrogate.csv")
    assert set(sur["kind"]) == {"surrogate"} and (sur["n_specimens"] <= 2).all()
    assert (tmp_path / "results/benchmarks/calibrate.tsv").exists()
    # values: a disc-only unit (w/o ALL) under a pure moment M rotates to the root of Eq. 3, T(phi) = M,
    # whatever the geometry. rupp2015 keeps the published disc law (data/characteristics/disc.csv, Table 1);
    # the calibrated set's disc is fitted to the derived rows (3 moments, 3 parameters: an exact interpolation)
    from scipy.optimize import brentq
    from lumbar.mechanics.elements.disc import torque_angle

    # the calibrated set's disc is the MAP fit's: the disc-only law of step 1 (fitted to the derived rows) scaled by
    # the posterior's disc-torque factors, so the calibrated rows follow the written law, not the derived rows
    discs = {"rupp2015": load_characteristic_set("rupp2015").disc.torque,
             "calibrated": load_characteristic_set("calibrated", data_dir=tmp_path / "results/calibration/"
                                                   "characteristics").disc.torque}
    wo_all = syn[syn["stage"] == "wo_all"].set_index(["set", "direction", "moment_nm"])
    assert len(wo_all) == 2 * 4 * len(moments) and wo_all["converged"].all()
    for (s, d, M), row in wo_all.iterrows():
        disc = discs[s]
        lo, hi = (np.radians(1.8), np.radians(15.6)) if d == "flexion" and disc[d][2] < 0 else (1e-9, np.radians(40))
        phi = np.degrees(brentq(lambda p: torque_angle(p, *disc[d])[0] - M, lo, hi, xtol=1e-14))
        assert row["rom_sim_deg"] == pytest.approx(phi, abs=1e-4), (s, d, M)
        if s == "calibrated":      # the posterior moves the law by at most two of its spreads (one derived curve per
            # direction is one observation of 25 % spread, beside a prior of the same spread): within 50 % of the row
            assert abs(row["rom_sim_deg"] - row["rom_mean_deg"]) <= 2 * 0.25 * row["rom_mean_deg"], (s, d, M)
    # Table 4's counts are the synopsis's outlier flags, per set
    counts = pd.read_csv(tmp_path / "results/tables/table4_outlier_counts.csv").set_index("set")
    assert counts["n_outliers"].to_dict() == syn.groupby("set")["outlier"].sum().to_dict()


def test_non_converged_scenario_flagged_with_residual_and_marked_in_table4(charset):
    """A disc-only unit loaded beyond the Eq. 3 flexion peak (10.19 N*m) has no equilibrium: the simulation
    row says converged=False with its residual and NaN ROM; the Table 4 synopsis marks it as a
    not-converged outlier and the counts report it."""
    from lumbar.experiments.fsu import build_fsu
    from lumbar.geometry.synthetic import symmetric_fsu

    sim = sr.simulate_stepwise_reduction(build_fsu(symmetric_fsu(), charset), stages=["wo_all"],
                                         directions=["flexion"], moments_nm=[10.0, 10.5], max_iter=30)
    row = sim.set_index("moment_nm")
    assert {"converged", "residual_force_n", "residual_moment_nm"} <= set(sim.columns)
    assert bool(row.loc[10.0, "converged"]) and not bool(row.loc[10.5, "converged"])
    assert row.loc[10.0, "residual_moment_nm"] <= 1e-6 and row.loc[10.5, "residual_moment_nm"] > 1e-3
    assert np.isnan(row.loc[10.5, "rom_deg"])
    sim.insert(0, "set", "test")
    ref = pd.DataFrame({"stage": "wo_all", "direction": "flexion", "moment_nm": [10.0, 10.5],
                        "rom_mean_deg": [13.4, 13.6], "rom_min_deg": [10.0, 10.0], "rom_max_deg": [20.0, 20.0],
                        "n_specimens": 8, "kind": "surrogate", "source": "test"})
    syn = sr.assess(sim, ref, "test").set_index("moment_nm")
    assert not bool(syn.loc[10.5, "converged"]) and bool(syn.loc[10.5, "outlier"])
    counts = sr.outlier_counts(syn.reset_index()).iloc[0]
    assert counts["n_not_converged"] == 1 and counts["n_outliers"] >= 1


def test_rest_state_a_saddle_hides_is_reached_by_cutting_the_structure_gradually():
    """Shirazi-Adl et al. (1986) set, stage w/o PLL: the disc's flexion law has a negative stiffness about zero
    (docs/validity.md) and the ALL left beside it is weak, so the reference is a saddle from which the modified Newton
    reaches no rest state. Removing the PLL gradually from the w/o VA rest state reaches a stable one (every
    eigenvalue of the symmetric tangent stiffness of the residual negative), between the neighbouring stages' rest
    rotations in flexion; the rows reached from the reference are not touched."""
    from lumbar.experiments.fsu import build_fsu
    from lumbar.geometry import load_geometry
    from lumbar.mechanics import so3
    from lumbar.mechanics.solve import continue_rest_states, solve
    fsu = build_fsu(load_geometry("visible_human", levels=["L4-L5"]), load_characteristic_set("shirazi_adl1986"))
    m = fsu.model
    fm, cm = fsu.masks(["wo_va", "wo_pll"])
    kw = dict(max_iter=50, tol_force=1e-9, tol_moment=1e-9)
    r0 = solve(m, np.zeros((2, m.nb, 6)), fmask=fm, cmask=cm, **kw)
    assert list(r0.converged) == [True, False]           # the case the continuation exists for
    before = (r0.x[0].copy(), r0.R[0].copy())
    r = continue_rest_states(m, r0, fm, cm, **kw)
    assert r.converged.all() and r.residual_force[1] < 1e-8 and r.residual_moment[1] < 1e-8
    assert np.array_equal(r.x[0], before[0]) and np.array_equal(r.R[0], before[1])
    J = m.evaluate(r.x[1:], r.R[1:], fmask=fm[1:], cmask=cm[1:])[1][0].reshape(6 * m.nb, 6 * m.nb)
    assert np.linalg.eigvalsh(0.5 * (J + J.T)).max() < 0.0
    flex = np.degrees(so3.log(r.R[:, 0])[:, 1])
    assert 0.0 < flex[0] < flex[1]          # cutting the PLL (posterior, in tension) lets the unit flex further


def test_rom_measured_from_a_saddle_is_flagged_in_the_table():
    """The disc-only stage's 0 N*m state at zero rotation is a saddle (the disc's flexion law has negative stiffness
    about zero, docs/validity.md): its rows say rest_state_stable = False; every stage a ligament still holds is
    stable. stable_rest_states itself: a state pushed off the saddle onto the stable branch (by a flexion moment,
    then unloaded at the branch's rest state found by continuation) is stable."""
    from lumbar.experiments.fsu import build_fsu
    from lumbar.geometry import load_geometry
    from lumbar.mechanics.solve import stable_rest_states
    fsu = build_fsu(load_geometry("visible_human", levels=["L4-L5"]), load_characteristic_set("calibrated"))
    out = sr.simulate_stepwise_reduction(fsu, moments_nm=[1.0], directions=["flexion"])
    stable = out.set_index("stage")["rest_state_stable"]
    assert not stable["wo_all"] and stable.drop("wo_all").all()
    m = fsu.model
    fm, cm = fsu.masks(["wo_all"])
    x, R = m.reference_state(1)
    assert not stable_rest_states(m, x, R, fm, cm)[0]
    from lumbar.experiments.fsu import moment_loads
    from lumbar.mechanics.solve import solve
    for M in (1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.0):     # down the stable flexion branch to its rest state
        r = solve(m, moment_loads(["flexion"], [M], m.nb), x0=x, R0=R, fmask=fm, cmask=cm, tol_force=1e-9,
                  tol_moment=1e-9)
        assert r.converged[0], M
        x, R = r.x, r.R
    assert stable_rest_states(m, x, R, fm, cm)[0]


def test_unreferenced_scenarios_names_what_a_measured_table_lacks():
    from lumbar.experiments.stepwise_reduction import unreferenced_scenarios

    sim = pd.DataFrame({"stage": ["intact", "intact", "wo_all", "wo_all"],
                        "direction": ["flexion", "flexion", "flexion", "flexion"],
                        "moment_nm": [5.0, 5.0, 10.0, 7.5]})                     # a specimen repeats a scenario
    ref = pd.DataFrame({"stage": ["intact", "wo_all"], "direction": ["flexion", "flexion"], "moment_nm": [5, 7.5]})
    assert unreferenced_scenarios(sim, ref) == ["wo_all flexion 10 N*m"]
    assert unreferenced_scenarios(sim.iloc[:2], ref) == []
