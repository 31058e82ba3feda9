"""OpenSim cross-check: one small case (L4-L5 w/o VA, 10 N*m flexion), lumbar's Newton solver and OpenSim's
forward dynamics to rest agree within 0.1 deg; and the OpenSim disc bushing applies lumbar's Eq. 3 torque.

``opensim`` is a test requirement (requirements-test.txt, installed by the README's test command and by
.ci/run), so this runs on every CI submission: a missing or broken opensim fails here, it is never skipped.
"""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import opensim as osim

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_opensim.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_opensim", BENCH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_opensim"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_flexion_10nm_agrees_within_0p1_deg(bench):
    out = bench.side_by_side("wo_va", moments=(10.0,), directions=("flexion",), repeat=1, n_large=8)
    assert not out["skipped"]
    (sc,) = out["scenarios"]
    assert sc["lumbar_converged"] and sc["opensim_settled"]
    assert np.isfinite(sc["rom_opensim_deg"]) and sc["rom_lumbar_deg"] > 5.0
    assert abs(sc["diff_deg"]) < 0.1
    assert out["agree_within_tolerance"]


def test_exact_disc_mapping_reproduces_lumbar_torque(bench):
    """The OpenSim rotation bushing applies lumbar's disc torque -T(log R) at a multi-axis pose."""
    from lumbar import so3
    from lumbar.elements.disc import disc_torque
    geo, cs = bench.load_case()
    f = bench.OpenSimFSU(osim, geo, cs, "wo_va", disc_mapping="exact")
    s = osim.State(f.state)
    q = s.getQ()
    for i, v in enumerate((0.12, -0.05, 0.08)):
        q.set(i, v)
    s.setQ(q)
    f.model.realizeDynamics(s)
    rot = osim.ExpressionBasedBushingForce.safeDownCast(f.model.getForceSet().get("disc_rotation"))
    vals, labels = rot.getRecordValues(s), rot.getRecordLabels()
    rec = {labels.get(i): vals.get(i) for i in range(vals.getSize())}
    torque = np.array([rec[f"disc_rotation.{geo.levels['L4-L5'].upper}_offset.torque.{c}"] for c in "XYZ"])
    R, _ = f.pose(s)
    T, _ = disc_torque(so3.log(R), cs.disc.torque)
    np.testing.assert_allclose(torque, -T, atol=1e-9)
