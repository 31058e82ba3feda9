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
