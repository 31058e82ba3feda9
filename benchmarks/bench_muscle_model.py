"""Benchmark: muscle redundancy solver (issues 5, 16), one core.

Prints one JSON object: cold solve time of one posture (upright standing, from the reference pose and zero
activations), the five validation activities as one batch, a sensitivity chunk (20 scenarios: SSL sweep x 4
scopes, standing, warm-started from the baseline) and a Sobol chunk (32 standing samples of the PCE training design), each with
the number of reached / KKT-certified postures and the largest KKT residual, and the estimate of the whole
default sensitivity study + Sobol (config/config.yaml) on 2 cores. Targets (issue 16): one posture < 1 s;
sensitivity + Sobol < 300 s on 2 cores. (Only the hand-written SQP: no IPOPT path exists yet.)
Usage: python benchmarks/bench_muscle_model.py
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import json  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from lumbar import muscle_model as mm  # noqa: E402

CONFIG = Path(__file__).resolve().parents[1] / "config" / "config.yaml"


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
    X = mm.sobol_samples(32, 1)
    t = time.perf_counter()
    sob = mm.sobol_evaluate(model, solver, {"standing": stand}, X, np.arange(len(X)), "standing")
    t_sobol = time.perf_counter() - t
    cfg = yaml.safe_load(CONFIG.read_text())["muscle_model"]
    n_sens = 288
    n_sobol = cfg["sobol"]["n_train"] * len(cfg["sensitivity"]["postures"])
    per = (t_sweep + t_sobol) / (len(out) + len(sob))
    print(json.dumps({
        "benchmark": "muscle_model",
        "model_build_s": round(t_build, 2),
        "one_posture_solve_s": round(t_one, 2), "one_posture_converged": bool(stand.converged),
        "one_posture_target_s": 1.0, "one_posture_kkt_residual": stand.kkt_residual,
        "validation_5_activities_s": round(t_val, 2),
        "validation_reached": int(sum(s.reached for s in sols)),
        "validation_certified": int(sum(s.certified for s in sols)),
        "validation_kkt_residuals": {a: float(f"{s.kkt_residual:.2e}") for a, s in zip(acts, sols)},
        "sweep_chunk_scenarios": int(len(out)), "sweep_chunk_s": round(t_sweep, 2),
        "sweep_chunk_reached": int(out["reached"].sum()), "sweep_chunk_certified": int(out["certified"].sum()),
        "sweep_chunk_kkt_max": float(out["kkt_residual"].max()),
        "sobol_chunk_samples": int(len(sob)), "sobol_chunk_s": round(t_sobol, 2),
        "sobol_chunk_reached": int(sob["reached"].sum()), "sobol_chunk_certified": int(sob["certified"].sum()),
        "warm_solve_s_per_scenario": round(per, 3),
        "default_study_solves": {"sensitivity": n_sens, "sobol": n_sobol, "sobol_n_train": cfg["sobol"]["n_train"]},
        "default_study_estimate_2_cores_s": round(per * (n_sens + n_sobol) / 2, 1),
        "default_study_target_s": 300.0,
    }, indent=1))


if __name__ == "__main__":
    main()
