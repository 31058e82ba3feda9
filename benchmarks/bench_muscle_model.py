"""Benchmark: muscle redundancy solver (issue 5), one core.

Prints one JSON object: cold solve time of one posture (upright standing, from the reference pose and zero
activations), the five validation activities as one batch, and a sensitivity chunk (20 scenarios: SSL
sweep x 4 scopes, standing, warm-started from the baseline). Targets: one posture < 2 s.
Usage: python benchmarks/bench_muscle_model.py
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import json  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402

from lumbar import muscle_model as mm  # noqa: E402


def main():
    logging.basicConfig(level=logging.ERROR)
    t = time.perf_counter()
    model = mm.LumbarMuscleModel()
    t_build = time.perf_counter() - t
    solver = mm.make_solver(model)
    t = time.perf_counter()
    stand = mm.solve_postures(model, solver, ["upright_standing"])[0]
    t_one = time.perf_counter() - t
    t = time.perf_counter()
    acts = list(mm.ACTIVITIES)
    sols = mm.solve_postures(model, solver, acts)
    t_val = time.perf_counter() - t
    rows = mm.sensitivity_rows("ssl_um", None, [2.0, 2.4, 2.8, 3.2, 3.6], ["MUL", "EXT", "EXT+PS", "ALL"],
                               ["standing"])
    t = time.perf_counter()
    out = mm.run_sensitivity(model, solver, rows, {"standing": stand})
    t_sweep = time.perf_counter() - t
    print(json.dumps({
        "benchmark": "muscle_model",
        "model_build_s": round(t_build, 2),
        "one_posture_solve_s": round(t_one, 2), "one_posture_converged": bool(stand.converged),
        "one_posture_target_s": 2.0,
        "validation_5_activities_s": round(t_val, 2),
        "validation_converged": int(sum(s.converged for s in sols)),
        "sweep_chunk_scenarios": int(len(out)), "sweep_chunk_s": round(t_sweep, 2),
        "sweep_chunk_converged": int(out["converged"].sum()),
        "sweep_full_estimate_s": round(t_sweep / len(out) * 288, 1),
    }, indent=1))


if __name__ == "__main__":
    main()
