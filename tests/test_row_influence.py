"""Which measured row decides which internal load (lumbar.experiments.calibration.influence): the judged internal
loads of a set, and the leave-one-row-out table around a fit. Controls that fail for the wrong mechanism."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from lumbar.experiments.calibration import influence as INF
from lumbar.geometry import load_geometry
from lumbar.inputs.characteristics import load_characteristic_set


@pytest.fixture(scope="module")
def geo():
    return load_geometry("visible_human", levels=["L4-L5"])


@pytest.fixture(scope="module")
def paper():
    return load_characteristic_set("rupp2015")          # every ligament, the ITL included


@pytest.fixture(scope="module")
def loads(geo, paper):
    return INF.internal_loads(geo, paper)


def _scaled(cs, kind, s):
    law = cs.ligaments[kind]        # a Rupp law: both force points scaled
    return dataclasses.replace(cs, ligaments={**cs.ligaments, kind: dataclasses.replace(law, f_a_n=law.f_a_n * s,
                                                                                        f_b_n=law.f_b_n * s)})


def test_internal_loads_follow_the_structure_that_carries_them(geo, paper, loads):
    """A ten times stronger ITL becomes the largest flexion ligament, with a larger moment than before, and the
    unit flexes less; a facet a thousand times softer carries (almost) nothing in extension."""
    assert loads["converged"]
    strong = INF.internal_loads(geo, _scaled(paper, "ITL", 10.0))
    assert strong["largest_flexion_ligament"] == "ITL"
    assert strong["itl_flexion_moment_nm"] > loads["itl_flexion_moment_nm"]
    assert strong["rom"]["flexion"] < loads["rom"]["flexion"]
    soft = INF.internal_loads(geo, dataclasses.replace(paper, facet=dataclasses.replace(
        paper.facet, stiffness=paper.facet.stiffness * 1e-3)))
    assert soft["facet_extension_7_5_n"] < 0.05 * max(loads["facet_extension_7_5_n"], 1.0)
    assert soft["rom"]["axial_rotation_left"] > loads["rom"]["axial_rotation_left"]


def _fake_fit(charset, shift=0.0):
    post = SimpleNamespace(names=["a", "b"], map_q=np.array([shift, 0.0]), prior_centre=np.zeros(2),
                           prior_sd=np.ones(2))
    return SimpleNamespace(posterior=post, charset=charset, cost=1.0, optimizer={"converged": True})


TARGETS = pd.DataFrame({"stage": "intact", "direction": ["flexion", "axial_rotation"], "moment_nm": 10.0,
                        "rom_mean_deg": [8.9, 2.2]})


def test_row_influence_table_predicts_the_left_out_row_and_reports_failures(geo, paper, loads):
    calls = []

    def refit(targets, start):
        calls.append((list(targets["direction"]), start))
        if "flexion" not in set(targets["direction"]):          # the fit without flexion fails
            raise RuntimeError("no equilibrium")
        return _fake_fit(paper, shift=2.5)

    tab = INF.row_influence(_fake_fit(paper), TARGETS, refit, geo)
    assert list(tab.columns) == list(INF.COLUMNS)
    assert list(tab["fit"]) == ["all rows (MAP)", "without flexion", "without axial_rotation"]
    # every refit starts from the full fit's optimum and sees the other rows only
    assert [c[0] for c in calls] == [["axial_rotation"], ["flexion"]]
    assert all(c[1] == {"a": 0.0, "b": 0.0} for c in calls)
    failed = tab[tab["left_out"] == "flexion"].iloc[0]
    assert not failed["converged"] and "failed: no equilibrium" in failed["largest_shifts"]
    ok = tab[tab["left_out"] == "axial_rotation"].iloc[0]
    # the left-out prediction is the refitted set's axial rotation at 10 N*m, not another direction's
    assert ok["left_out_predicted_deg"] == pytest.approx(loads["rom"]["axial_rotation_left"])
    assert ok["left_out_predicted_deg"] != pytest.approx(loads["rom"]["flexion"])
    assert ok["left_out_rel_error"] == pytest.approx((ok["left_out_predicted_deg"] - 2.2) / 2.2)
    assert ok["largest_shifts"].startswith("a +2.5 sd")
    assert np.isnan(tab.iloc[0]["left_out_measured_deg"])


def test_facet_profile_holds_each_value_and_starts_from_the_map(geo, paper):
    calls = []

    def refit_held(targets, start, value):
        calls.append((list(targets["direction"]), start, value))
        if value > 5e5:
            raise RuntimeError("no equilibrium")
        return _fake_fit(dataclasses.replace(paper, facet=dataclasses.replace(paper.facet, stiffness=value)))

    tab = INF.facet_profile(_fake_fit(paper), TARGETS, refit_held, geo, values=(1e4, 1e6))
    assert list(tab.columns) == list(INF.COLUMNS)
    assert [c[2] for c in calls] == [1e4, 1e6]
    assert all(c[0] == ["flexion", "axial_rotation"] and c[1] == {"a": 0.0, "b": 0.0} for c in calls)   # every row
    ok, failed = tab.iloc[0], tab.iloc[1]
    assert ok["facet_stiffness_held"] == 1e4 and ok["facet_stiffness_n_per_m"] == pytest.approx(1e4)
    assert ok["left_out"] == "" and ok["converged"]
    assert not failed["converged"] and "failed: no equilibrium" in failed["largest_shifts"]
    # the held value reaches the unit: a softer facet carries less in extension than the paper's set
    soft = INF.internal_loads(geo, dataclasses.replace(paper, facet=dataclasses.replace(paper.facet, stiffness=1e4)))
    assert ok["facet_extension_7_5_n"] == pytest.approx(soft["facet_extension_7_5_n"])


def test_profile_sentence_names_the_stiffest_value_with_physiological_loads():
    from lumbar.report.influence_text import influence_sentence, profile_sentence
    base = {"converged": True, "cost": 1.0, "rom_flexion_deg": 7.0, "rom_extension_deg": 4.6,
            "rom_lateral_bending_deg": 5.3, "facet_axial_rotation_7_5_n": 100.0, "facet_flexion_7_5_n": 0.0,
            "itl_flexion_moment_nm": 1.0, "isl_flexion_moment_nm": 2.0, "flexion_reduction_monotone": True,
            "largest_shifts": "facet_stiffness +1.0 sd"}
    rows = [dict(base, fit="all rows (MAP)", left_out="", facet_stiffness_held=np.nan, facet_stiffness_n_per_m=2.7e6,
                 facet_extension_7_5_n=127.0, largest_flexion_ligament="ITL", ssl_flexion_tension_n=4.7,
                 rom_axial_rotation_deg=2.73),
            dict(base, fit="without axial_rotation", left_out="axial_rotation", facet_stiffness_held=np.nan,
                 facet_stiffness_n_per_m=1e4, facet_extension_7_5_n=6.0, largest_flexion_ligament="CL",
                 ssl_flexion_tension_n=9.0, rom_axial_rotation_deg=5.3, left_out_measured_deg=2.2,
                 left_out_predicted_deg=5.3, left_out_rel_error=1.4, largest_shifts="FL:scale +0.4 sd"),
            dict(base, fit="held 1e5", left_out="", facet_stiffness_held=1e5, facet_stiffness_n_per_m=1e5,
                 facet_extension_7_5_n=35.0, largest_flexion_ligament="ISL", ssl_flexion_tension_n=6.1,
                 rom_axial_rotation_deg=2.91),
            dict(base, fit="held 3e5", left_out="", facet_stiffness_held=3e5, facet_stiffness_n_per_m=3e5,
                 facet_extension_7_5_n=66.0, largest_flexion_ligament="ISL", ssl_flexion_tension_n=5.6,
                 rom_axial_rotation_deg=2.84),
            dict(base, fit="held 1e6", left_out="", facet_stiffness_held=1e6, facet_stiffness_n_per_m=1e6,
                 facet_extension_7_5_n=104.0, largest_flexion_ligament="ISL", ssl_flexion_tension_n=2.8,
                 rom_axial_rotation_deg=2.76)]
    t = pd.DataFrame(rows)
    fmt = lambda v, d=3: f"{float(v):.{d}g}"            # noqa: E731
    s = profile_sentence(t, fmt)
    assert "Held at 3e+05 N/m" in s and "2.84 deg" in s and "29 %" in s        # 1e6 fails the facet force
    # the held rows are neither the MAP nor a left-out row of the influence sentence
    assert "instead of 2.7e+06" in influence_sentence(t, fmt)
    # control: without a row in range the sentence says so, and without profile rows it is empty
    t2 = t.copy()
    t2.loc[t2["facet_stiffness_held"].notna(), "ssl_flexion_tension_n"] = 1.0
    assert "does not bring" in profile_sentence(t2, fmt)
    assert profile_sentence(t[t["facet_stiffness_held"].isna()], fmt) == ""


def test_disc_spread_profile_passes_each_spread_and_records_the_disc_scale(geo, paper):
    calls = []

    def refit_spread(targets, start, spread):
        calls.append((list(targets["direction"]), start, spread))
        return _fake_fit(paper)

    tab = INF.disc_spread_profile(_fake_fit(paper), TARGETS, refit_spread, geo, values=(0.35, 0.5))
    assert list(tab.columns) == list(INF.COLUMNS)
    assert [c[2] for c in calls] == [0.35, 0.5]
    assert all(c[0] == ["flexion", "axial_rotation"] and c[1] == {"a": 0.0, "b": 0.0} for c in calls)
    assert list(tab["disc_row_spread"]) == [0.35, 0.5] and tab["facet_stiffness_held"].isna().all()
    assert (tab["left_out"] == "").all()


def test_spread_sentence_names_the_smallest_spread_with_physiological_loads_and_is_not_the_map():
    from lumbar.report.influence_text import influence_sentence, profile_sentence, spread_sentence
    base = {"converged": True, "cost": 1.0, "rom_flexion_deg": 7.0, "rom_extension_deg": 4.6,
            "rom_lateral_bending_deg": 5.3, "rom_axial_rotation_deg": 2.7, "facet_axial_rotation_7_5_n": 100.0,
            "facet_flexion_7_5_n": 0.0, "itl_flexion_moment_nm": 1.0, "isl_flexion_moment_nm": 2.0,
            "flexion_reduction_monotone": True, "largest_shifts": "facet_stiffness +1.0 sd", "left_out": "",
            "facet_stiffness_held": np.nan, "largest_flexion_ligament": "ISL"}
    rows = [dict(base, fit="all rows (MAP)", disc_row_spread=np.nan, facet_stiffness_n_per_m=1.4e6,
                 disc_axial_rotation_scale=1.5, facet_extension_7_5_n=115.0, ssl_flexion_tension_n=2.7),
            dict(base, fit="without axial_rotation", left_out="axial_rotation", disc_row_spread=np.nan,
                 facet_stiffness_n_per_m=1e4, disc_axial_rotation_scale=1.0, facet_extension_7_5_n=6.0,
                 ssl_flexion_tension_n=9.0, left_out_measured_deg=2.2, left_out_predicted_deg=5.3,
                 left_out_rel_error=1.4, largest_shifts="FL:scale +0.4 sd"),
            dict(base, fit="35 %", disc_row_spread=0.35, facet_stiffness_n_per_m=1e6, disc_axial_rotation_scale=1.7,
                 facet_extension_7_5_n=105.0, ssl_flexion_tension_n=3.0),
            dict(base, fit="50 %", disc_row_spread=0.5, facet_stiffness_n_per_m=7e5, disc_axial_rotation_scale=2.1,
                 facet_extension_7_5_n=88.0, ssl_flexion_tension_n=5.5)]
    t = pd.DataFrame(rows)
    fmt = lambda v, d=3: f"{float(v):.{d}g}"            # noqa: E731
    s = spread_sentence(t, fmt)
    assert "50 %: disc axial-rotation law 2.1 x" in s and "from a spread of 50 % on" in s
    # the spread rows are neither the MAP of the influence sentence nor profile rows
    assert "instead of 1.4e+06" in influence_sentence(t, fmt)
    assert profile_sentence(t, fmt) == ""
    # control: with the SSL below 5 N in every spread row, no spread brings the loads into range
    t2 = t.copy()
    t2.loc[t2["disc_row_spread"].notna(), "ssl_flexion_tension_n"] = 3.0
    assert "no spread tried" in spread_sentence(t2, fmt)
    assert spread_sentence(t[t["disc_row_spread"].isna()], fmt) == ""


def test_influence_sentence_keeps_a_stopped_refit_and_is_silent_when_no_row_moves_the_map_nearer_its_priors():
    from lumbar.report.influence_text import influence_sentence
    base = {"cost": 1.0, "rom_flexion_deg": 7.0, "rom_extension_deg": 4.6, "rom_lateral_bending_deg": 5.3,
            "rom_axial_rotation_deg": 2.7, "facet_axial_rotation_7_5_n": 100.0, "facet_extension_7_5_n": 110.0,
            "largest_flexion_ligament": "ISL", "facet_stiffness_held": np.nan, "disc_row_spread": np.nan,
            "facet_stiffness_n_per_m": 1.4e6, "left_out_measured_deg": np.nan, "left_out_predicted_deg": np.nan,
            "left_out_rel_error": np.nan}
    t = pd.DataFrame([
        dict(base, fit="all rows (MAP)", left_out="", converged=True, largest_shifts="facet_stiffness +2.1 sd"),
        dict(base, fit="without lateral_bending", left_out="lateral_bending", converged=True,
             largest_shifts="facet_stiffness +2.1 sd", left_out_measured_deg=5.7, left_out_predicted_deg=5.4,
             left_out_rel_error=-0.05),
        dict(base, fit="without axial_rotation", left_out="axial_rotation", converged=False,
             largest_shifts="FL:scale +0.4 sd", facet_stiffness_n_per_m=1.1e4, facet_extension_7_5_n=6.0,
             left_out_measured_deg=2.2, left_out_predicted_deg=5.4, left_out_rel_error=1.45)])
    fmt = lambda v, d=3: f"{float(v):.{d}g}"            # noqa: E731
    s = influence_sentence(t, fmt)
    # the refit that stopped at its budget is still the row that frees the MAP, and is named as stopped
    assert s.startswith("Without the axial rotation row (a diagnostic refit that stopped") and "1.1e+04" in s
    # control: a table whose left-out rows all shift as far as the MAP names no row (not one identical to the MAP)
    assert influence_sentence(t.iloc[:2], fmt) == ""


def test_influence_job_refuses_a_map_other_than_the_shipped_one():
    """The influence and draws rules rerun the calibration; their tables must describe the shipped MAP. Rounding of
    the CSV (six significant digits) passes; a different fit fails, naming the parameter (control: the same table
    passes)."""
    import pandas as pd
    import pytest

    from lumbar.experiments import calibration as mod

    shipped = pd.DataFrame({"parameter": ["ISL:scale", "facet_stiffness"], "map_fit": [0.571398, 6.13522]})
    rounded = shipped.assign(map_fit=[0.5713984, 6.135224])
    mod.check_same_map(shipped, shipped, "posterior.csv")
    mod.check_same_map(shipped, rounded, "posterior.csv")
    with pytest.raises(RuntimeError, match="facet_stiffness"):
        mod.check_same_map(shipped, shipped.assign(map_fit=[0.571398, 6.2]), "posterior.csv")
    with pytest.raises(RuntimeError, match="fitted"):
        mod.check_same_map(shipped, shipped.iloc[:1], "posterior.csv")
