"""Validation on real data (lumbar.experiments.validation) and the split outlier counts of Tables 4 and 5."""
import numpy as np
import pandas as pd
import pytest

from lumbar.experiments import l2s1, validation as V
from lumbar.plots.validation import plot_scoreboard
from lumbar.experiments.stepwise_reduction import outlier_counts


def _synopsis():
    rows = []
    for kind, outl in (("surrogate", True), ("surrogate", False), ("derived_from_published_fit", True),
                       ("original_text", False), ("original_text", True)):
        rows.append({"set": "calibrated", "stage": "intact", "direction": "flexion", "moment_nm": 10.0,
                     "rom_sim_deg": 1.0, "rom_mean_deg": 1.0, "rom_min_deg": np.nan, "rom_max_deg": np.nan,
                     "outlier": outl, "converged": True, "data_kind": kind})
    return pd.DataFrame(rows)


def test_table4_counts_split_real_from_surrogate_rows():
    c = outlier_counts(_synopsis()).set_index("set").loc["calibrated"]
    assert (c["n_scenarios"], c["n_outliers"]) == (5, 3)
    assert (c["n_scenarios_real"], c["n_outliers_real"]) == (3, 2)
    assert "method check" in c["surrogate_comparison"]
    measured = outlier_counts(_synopsis().assign(data_kind="measured")).set_index("set").loc["calibrated"]
    assert "method check" not in measured["surrogate_comparison"]


def test_table5_counts_split_real_from_surrogate_rows():
    syn = _synopsis().rename(columns={})
    c = l2s1.outlier_counts(syn).set_index("set").loc["calibrated"]
    assert (c["scenarios"], c["outliers"], c["n_scenarios_real"], c["n_outliers_real"]) == (5, 3, 3, 2)


@pytest.mark.parametrize("sim, measured, lo, hi, within", [
    (10.0, 8.0, np.nan, np.nan, True),       # 25 % of 8 = 2
    (10.1, 8.0, np.nan, np.nan, False),
    (5.0, 8.0, 4.0, 6.0, True),              # a published range wins over the relative rule
    (7.0, 8.0, 4.0, 6.0, False),
    (np.nan, 8.0, np.nan, np.nan, False),    # no equilibrium is never "within"
])
def test_within_rule(sim, measured, lo, hi, within):
    assert V._within(sim, measured, lo, hi)[0] is within


def test_rom_rows_take_the_disc_fits_real_rows_as_calibration_targets():
    """The disc-only rows with a real reference (derived from the published fit, or a measured table's) are what the
    disc law is fitted to: targets. Surrogate rows and the other stages' rows give none (the intact rows the
    final fit used come from measured_rom_rows)."""
    syn = pd.concat([_synopsis(), _synopsis().assign(stage="wo_all")], ignore_index=True)
    syn.loc[len(syn)] = {**syn.iloc[-1].to_dict(), "data_kind": "measured", "rom_min_deg": 0.5, "rom_max_deg": 0.9}
    rows = V.rom_rows(syn)
    assert [r["kind"] for r in rows] == ["derived_from_published_fit", "original_text", "original_text", "measured"]
    assert all(r["role"] == V.TARGET and r["condition"].startswith("wo_all") for r in rows)
    assert rows[-1]["within"] is False and rows[-1]["tolerance_rule"] == "measured range"    # 1.0 outside 0.5-0.9
    # a literature set's disc is the paper's, not fitted to a measured table: its rows are Table 4's, not targets
    assert len(V.rom_rows(syn.assign(set="rupp2015"))) == 1                 # the derived row only


def test_in_vivo_rows_flag_unconverged_postures():
    df = pd.DataFrame({"activity": ["a", "b"], "idp_sim_mpa": [0.5, 0.5], "idp_in_vivo_mpa": [0.5, 0.5],
                       "converged": [True, False], "kind": ["original_text"] * 2, "source": ["s"] * 2})
    r = V.in_vivo_rows(df)
    assert r[0]["within"] and not r[1]["within"] and np.isnan(r[1]["sim"])
    assert {x["role"] for x in r} == {V.INDEPENDENT}


def _scoreboard_rows(levels=()):
    rows = []
    for s in ("calibrated", "rupp2015", "nolte1990"):          # the same disc-only comparison for three sets
        rows.append(dict(quantity="L4-L5 ROM", condition="wo_all flexion 5 N*m", unit="deg", sim=8.4291 + 1e-6,
                         measured=8.4291, measured_low=np.nan, measured_high=np.nan, within=True,
                         tolerance_rule="measured +- 0.5", set=s, role="calibration target"))
    rows.append(dict(quantity="L4-L5 IDP in vivo", condition="crate_far", unit="MPa", sim=np.nan, measured=1.8,
                     measured_low=np.nan, measured_high=np.nan, within=False,
                     tolerance_rule="no simulated value (no equilibrium)", set="muscle model", role="independent"))
    rows.append(dict(quantity="facet joint space width", condition="lumbar", unit="mm", sim=1.68, measured=1.93,
                     measured_low=1.42, measured_high=2.44, within=True, tolerance_rule="measured range",
                     set="geometry", role="independent"))
    for lv in levels:                                            # other levels' ROM: a new quantity each
        for d, sim in (("flexion", 8.0), ("extension", 2.0)):
            rows.append(dict(quantity=f"{lv} ROM", condition=f"intact {d} 10 N*m", unit="deg", sim=sim,
                             measured=6.0, measured_low=np.nan, measured_high=np.nan,
                             within=abs(sim - 6.0) <= 1.5, tolerance_rule="measured +- 25 % (no range published)",
                             set="calibrated", role="independent"))
    return pd.DataFrame([{**r, "kind": "original_text", "source": "s", "note": ""} for r in rows])


def test_distinct_comparisons_count_shared_rows_once_and_bands_follow_the_rule():
    d = V.distinct_comparisons(_scoreboard_rows())
    assert len(d) == 3 and list(d["role"]) == ["independent", "independent", "calibration target"]
    disc = d[d["role"] == "calibration target"].iloc[0]
    assert disc["n_rows"] == 3 and disc["sets"] == "calibrated; rupp2015; nolte1990"
    assert (disc["band_low"], disc["band_high"]) == pytest.approx((7.9291, 8.9291))
    assert V.role_counts(d) == {"independent": (1, 2), "calibration target": (1, 1)}
    facet = d[d["quantity"] == "facet joint space width"].iloc[0]
    assert (facet["band_low"], facet["band_high"]) == (1.42, 2.44)               # the published range
    row = {"measured": 6.0, "measured_low": np.nan, "measured_high": np.nan, "tolerance_rule": "measured +- 25 %"}
    assert V.acceptance_band(row) == pytest.approx((4.5, 7.5))
    # a simulated value that differs beyond 3 significant digits is another comparison
    df = _scoreboard_rows()
    df.loc[1, "sim"] = 8.6
    assert len(V.distinct_comparisons(df)) == 4
    assert V.condition_label("wo_all lateral_bending 7.5 N*m") == "w/o ALL lateral bending 7.5 N\u00b7m"


def test_scoreboard_figure_grows_with_new_quantities(tmp_path):
    """Generic over the rows: another level's ROM rows are new panels, and the figure grows to hold them."""
    from PIL import Image

    a, b = tmp_path / "a.png", tmp_path / "b.png"
    plot_scoreboard(_scoreboard_rows(), a)
    plot_scoreboard(_scoreboard_rows(levels=("L1-L2", "L2-L3", "L3-L4", "L5-S1")), b)
    (wa, ha), (wb, hb) = Image.open(a).size, Image.open(b).size
    assert wa == wb and hb > ha * 1.5
    plot_scoreboard(_scoreboard_rows().iloc[0:0], tmp_path / "empty.png")       # no row: a figure that says so
    assert (tmp_path / "empty.png").stat().st_size > 0


def test_fitted_mask_names_exactly_the_rows_the_calibration_was_pinned_to():
    """A real-target file's rows are calibration targets only where the calibration's final fit used them (same
    scenario, value and source); the same scenario from another source, or another value, is independent."""
    real = pd.DataFrame({"stage": "intact", "direction": ["flexion", "extension", "flexion"], "moment_nm": 10.0,
                         "rom_mean_deg": [8.9, 5.8, 8.9], "source": ["Yamamoto", "Yamamoto", "Heuer"]})
    fitted = pd.DataFrame({"stage": ["intact"], "direction": ["flexion"], "moment_nm": [10], "rom_mean_deg": [8.9],
                           "source": ["Yamamoto"]})
    assert V.fitted_mask(real, fitted).tolist() == [True, False, False]
    assert V.fitted_mask(real, fitted.iloc[:0]).tolist() == [False, False, False]
    assert V.fitted_mask(real.iloc[:0], fitted).tolist() == []


def test_measured_in_vitro_idp_rows_are_independent_and_judged_by_table5s_rule():
    syn = pd.DataFrame({"set": ["calibrated", "calibrated", "rupp2015"], "muscle_setup": ["none", "all", "none"],
                        "load_case": ["neutral", "flexion", "neutral"], "idp_sim_mpa": [0.30, 0.55, 0.2],
                        "idp_mean_mpa": [0.25, 0.40, 0.25], "idp_sd_mpa": [0.06, 0.10, 0.06], "outlier": False,
                        "converged": [True, True, True], "data_kind": "measured"})
    table = pd.DataFrame({"muscle_setup": ["none", "all"], "load_case": ["neutral", "flexion"],
                          "source": ["Wilke 1996, Table 2", "Wilke 1996, Table 2"]})
    rows = V.idp_in_vitro_rows(syn, table)
    assert [r["within"] for r in rows] == [True, False]            # 0.30 in 0.25 +- 0.06; 0.55 outside 0.40 +- 0.10
    assert all(r["role"] == V.INDEPENDENT and r["set"] == "calibrated" for r in rows)
    assert rows[0]["source"] == "Wilke 1996, Table 2" and rows[0]["measured_low"] == pytest.approx(0.19)
    assert V.idp_in_vitro_rows(syn.assign(data_kind="surrogate"), table) == []   # a method check, not validation


def test_near_limit_names_the_rows_a_small_change_can_flip():
    rom = pd.DataFrame({"level": ["A", "B", "C", "D", "E"], "ratio": [1.247, 1.29, 0.74, 1.0, 2.15],
                        "within": [True, False, False, True, False]})
    assert V.near_limit(rom)["level"].tolist() == ["A", "B", "C"]
    assert V.near_limit(rom, band=0.02)["level"].tolist() == ["A", "C"]
