"""Validation on real data (lumbar.experiments.validation) and the split outlier counts of Tables 4 and 5."""
import numpy as np
import pandas as pd
import pytest

from lumbar.experiments import l2s1, validation as V
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


def test_rom_rows_take_only_published_fit_rows_as_calibration_targets():
    rows = V.rom_rows(_synopsis())
    assert len(rows) == 1 and rows[0]["role"] == V.TARGET and rows[0]["kind"] == "derived_from_published_fit"


def test_in_vivo_rows_flag_unconverged_postures():
    df = pd.DataFrame({"activity": ["a", "b"], "idp_sim_mpa": [0.5, 0.5], "idp_in_vivo_mpa": [0.5, 0.5],
                       "converged": [True, False], "kind": ["original_text"] * 2, "source": ["s"] * 2})
    r = V.in_vivo_rows(df)
    assert r[0]["within"] and not r[1]["within"] and np.isnan(r[1]["sim"])
    assert {x["role"] for x in r} == {V.INDEPENDENT}
