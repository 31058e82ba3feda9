"""The job profile (lumbar.mechanics.profile): phases exclusive of nested ones, counts, a no-op when off, and the
file a profiled process writes at exit with the equilibria it solved."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time

import pytest

from lumbar.mechanics import profile


@pytest.fixture
def on(monkeypatch):
    state = {"on": True, "job": None, "stack": [], "phases": dict.fromkeys(profile.PHASES, 0.0),
             "counts": dict.fromkeys(profile.COUNTS, 0)}
    monkeypatch.setattr(profile, "_state", state)
    return state


def test_nested_phase_counts_only_its_own_time(on):
    with profile.phase("fsu_solve"):
        time.sleep(0.02)
        with profile.phase("numba_load"):
            time.sleep(0.06)
    assert on["phases"]["numba_load"] >= 0.06
    # exclusive: the outer phase keeps its own 0.02 s, not the 0.08 s of the block
    assert 0.02 <= on["phases"]["fsu_solve"] < 0.05
    assert not on["stack"]


def test_counts_and_unknown_names_refused(on):
    profile.count("equilibria", 7)
    profile.count("equilibria")
    assert on["counts"]["equilibria"] == 8
    with pytest.raises(ValueError, match="unknown profile counter"):
        profile.count("equilibrium")
    with pytest.raises(ValueError, match="unknown profile phase"):
        with profile.phase("solving"):
            pass


def test_off_is_a_no_op(monkeypatch):
    state = {"on": False, "job": None, "stack": [], "phases": dict.fromkeys(profile.PHASES, 0.0),
             "counts": dict.fromkeys(profile.COUNTS, 0)}
    monkeypatch.setattr(profile, "_state", state)
    with profile.phase("fsu_solve"):
        profile.count("equilibria", 3)
    profile.start_job("rule")
    assert state["counts"]["equilibria"] == 0 and state["phases"]["fsu_solve"] == 0.0 and state["job"] is None
    assert profile.write() is None


def test_rest_is_what_the_phases_leave(on):
    on["t0"] = time.perf_counter() - 1.0
    on["phases"]["startup_imports"] = 0.25
    on["phases"]["fsu_solve"] = 0.5
    rec = profile.record()
    assert rec["phases_s"]["rest"] == pytest.approx(rec["wall_s"] - 0.75, abs=1e-3)
    assert sum(rec["phases_s"].values()) == pytest.approx(rec["wall_s"], abs=1e-3)


def test_a_profiled_process_writes_its_solves_at_exit(tmp_path):
    """A process that solves 3 + 2 equilibria on the synthetic unit writes one file with 5 equilibria, a positive
    start-up time and phases that sum to its wall time."""
    code = textwrap.dedent("""
        import numpy as np
        from lumbar.mechanics import profile
        profile.start_job("demo", "set=a")
        from lumbar.experiments.fsu import build_fsu
        from lumbar.geometry import load_geometry
        from lumbar.inputs.characteristics import load_characteristic_set
        from lumbar.mechanics.solve import solve
        fsu = build_fsu(load_geometry("synthetic"), load_characteristic_set("calibrated"))
        for B in (3, 2):
            loads = np.zeros((B, 1, 6))
            loads[:, 0, 4] = 2.0
            solve(fsu.model, loads)
    """)
    env = dict(os.environ, LUMBAR_PROFILE_DIR=str(tmp_path))
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    files = list(tmp_path.glob("demo__set=a__*.json"))
    assert len(files) == 1
    rec = json.loads(files[0].read_text())
    assert rec["rule"] == "demo" and rec["job"] == "set=a"
    assert rec["counts"]["equilibria"] == 5
    assert rec["phases_s"]["startup_imports"] > 0 and rec["phases_s"]["fsu_solve"] > 0
    assert sum(rec["phases_s"].values()) == pytest.approx(rec["wall_s"], rel=1e-3, abs=1e-3)
