"""Benchmark: backward calibration wall time and 960 forward equilibria (6 sets x 160 scenarios), one core.

Prints one JSON object. The calibration runs as the workflow's (default geometry: the embedded Visible Human
L4-L5; family scaled_published; real targets: Yamamoto et al. 1989 intact ROM; step-0 anchoring and final
real-target step) on a noise-free surrogate of the anchored model (1 virtual specimen, no variation).
Baseline measured in the same run: the same calibration with the former monotone family and no real
targets. Targets: calibration < 30 s, 960 forward equilibria < 2 s. Usage: python benchmarks/bench_calibration.py
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import dataclasses  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402

from pathlib import Path  # noqa: E402

from lumbar.experiments.calibration import calibrate, fit_real_targets  # noqa: E402
from lumbar.inputs.characteristics import CHARACTERISTIC_SETS, load_characteristic_set  # noqa: E402
from lumbar.experiments.fsu import build_fsu  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.experiments.stepwise_reduction import read_experiment_table, reference_table, simulate_stepwise_reduction  # noqa: E402
from lumbar.experiments.virtual_experiment import SpecimenVariation, stepwise_reduction_table  # noqa: E402


def main():
    logging.basicConfig(level=logging.ERROR)
    geo = load_geometry("visible_human", levels=["L4-L5"])
    paper = load_characteristic_set("calibrated")
    real = read_experiment_table(Path(__file__).resolve().parents[1] / "data" / "experiments" /
                                 "yamamoto1989_intact_rom_original_text.csv")
    anchored = fit_real_targets(geo, paper, real).charset
    zero = SpecimenVariation(**{f.name: 0.0 for f in dataclasses.fields(SpecimenVariation)})
    table = stepwise_reduction_table(geo, anchored, 1, n_specimens=1, variation=zero, noise_sd_deg=0.0)
    ref = reference_table(table, real=real)
    t = time.perf_counter()
    res = calibrate(geo, ref, initial=paper, family="scaled_published", real_targets=real)
    t_cal = time.perf_counter() - t
    t = time.perf_counter()
    calibrate(geo, reference_table(table), initial=paper, family="monotone")
    t_base = time.perf_counter() - t
    fsus = [build_fsu(geo, res.charset if n == "calibrated" else load_characteristic_set(n))
            for n in CHARACTERISTIC_SETS]
    t = time.perf_counter()
    n = conv = 0
    for f in fsus:
        sim = simulate_stepwise_reduction(f)
        n += len(sim)
        conv += int(sim["converged"].sum())
    t_fwd = time.perf_counter() - t
    print(json.dumps({
        "calibration_wall_time_s": round(t_cal, 2), "calibration_target_s": 30,
        "baseline_monotone_no_real_targets_s": round(t_base, 2), "ratio_to_baseline": round(t_cal / t_base, 3),
        "calibration_evaluations": int(res.summary["n_evaluations"].sum()),
        "forward_equilibria": n, "forward_converged": conv,
        "forward_time_s": round(t_fwd, 3), "forward_target_s": 2.0,
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
    }, indent=2))


if __name__ == "__main__":
    main()
