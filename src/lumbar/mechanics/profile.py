"""Where a workflow job's time goes: phase times and equilibrium counts of one process (off by default).

With the environment variable ``LUMBAR_PROFILE_DIR`` set, a process that calls :func:`start_job` (every workflow
script does, through ``workflow/scripts/_common.py``) writes one JSON file into that folder when it exits::

    {"rule": ..., "job": ..., "pid": ..., "wall_s": ..., "cpu_s": ...,
     "phases_s": {"startup_imports": ..., "numba_load": ..., "geometry": ..., "fsu_solve": ...,
                  "muscle_solve": ..., "rest": ...},
     "counts": {"equilibria": ..., "muscle_postures": ...}}

``startup_imports`` runs from the process's start (``/proc/self/stat``) to :func:`start_job` (the interpreter,
Snakemake's script preamble and the script's module imports); the other phases are the library's own
:func:`phase` blocks, each counted exclusive of the phases inside it (the compiled core's first use inside a solve
is ``numba_load``, not ``fsu_solve``); ``rest`` is what is left (tables, figures, optimisers' bookkeeping, anything
not in a phase). ``equilibria`` counts every batch member of a Newton solve (:func:`lumbar.mechanics.solve.newton`,
each load step of a continuation is one); ``muscle_postures`` every posture the muscle model's redundancy solver is
asked for. ``benchmarks/bench_dag.py`` sums the files of a DAG run per rule into ``dag_profile.json``.

Without the variable every function here is a no-op of a dictionary lookup. No lumbar import (layer 0).
"""
from __future__ import annotations

import atexit
import contextlib
import json
import os
import re
import time
from pathlib import Path

ENV = "LUMBAR_PROFILE_DIR"
PHASES = ("startup_imports", "numba_load", "geometry", "fsu_solve", "muscle_solve", "rest")
COUNTS = ("equilibria", "muscle_postures")

_state: dict = {"on": bool(os.environ.get(ENV)), "job": None, "stack": [],
                "phases": dict.fromkeys(PHASES, 0.0), "counts": dict.fromkeys(COUNTS, 0)}


def enabled() -> bool:
    return _state["on"]


def process_age_s() -> float | None:
    """Seconds since this process started (Linux ``/proc``), or None where that cannot be read."""
    try:
        stat = Path("/proc/self/stat").read_text()
        start_ticks = float(stat.rsplit(")", 1)[1].split()[19])     # field 22: starttime, clock ticks after boot
        uptime = float(Path("/proc/uptime").read_text().split()[0])
        return max(uptime - start_ticks / os.sysconf("SC_CLK_TCK"), 0.0)
    except (OSError, ValueError, IndexError):
        return None


@contextlib.contextmanager
def phase(name: str):
    """Count the block's wall time to ``name`` (one of :data:`PHASES`), exclusive of phases nested in it."""
    if not _state["on"]:
        yield
        return
    if name not in _state["phases"]:
        raise ValueError(f"unknown profile phase {name!r}; expected one of {PHASES}")
    frame = [time.perf_counter(), 0.0]
    _state["stack"].append(frame)
    try:
        yield
    finally:
        _state["stack"].pop()
        total = time.perf_counter() - frame[0]
        _state["phases"][name] += total - frame[1]
        if _state["stack"]:
            _state["stack"][-1][1] += total


def count(name: str, n: int = 1) -> None:
    """Add ``n`` to the counter ``name`` (one of :data:`COUNTS`)."""
    if _state["on"]:
        if name not in _state["counts"]:
            raise ValueError(f"unknown profile counter {name!r}; expected one of {COUNTS}")
        _state["counts"][name] += int(n)


def start_job(rule: str, job: str = "") -> None:
    """Mark the end of start-up and imports for the job ``job`` of ``rule`` and write its profile at exit."""
    if not _state["on"] or _state["job"] is not None:
        return
    age = process_age_s()
    _state["t0"] = time.perf_counter() - (age or 0.0)
    _state["phases"]["startup_imports"] = age or 0.0
    _state["job"] = (str(rule), str(job))
    atexit.register(write)


def record() -> dict:
    """This process's profile so far (see the module docstring)."""
    wall = time.perf_counter() - _state.get("t0", time.perf_counter())
    phases = dict(_state["phases"])
    phases["rest"] = max(wall - sum(v for k, v in phases.items() if k != "rest"), 0.0)
    t = os.times()
    rule, job = _state["job"] or ("", "")
    return {"rule": rule, "job": job, "pid": os.getpid(), "wall_s": round(wall, 4),
            "cpu_s": round(t.user + t.system, 4), "phases_s": {k: round(v, 4) for k, v in phases.items()},
            "counts": dict(_state["counts"])}


def write() -> Path | None:
    """Write :func:`record` to ``$LUMBAR_PROFILE_DIR/<rule>__<job>__<pid>.json``; returns the path."""
    folder = os.environ.get(ENV)
    if not folder or _state["job"] is None:
        return None
    rec = record()
    stem = re.sub(r"[^A-Za-z0-9_.=-]+", "_", f"{rec['rule']}__{rec['job']}__{rec['pid']}")
    path = Path(folder) / f"{stem}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(rec, indent=1, sort_keys=True))
    return path
