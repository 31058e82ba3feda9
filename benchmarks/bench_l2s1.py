"""Benchmark: the 294 L2-S1 equilibria of Table 5 (6 characteristic sets x 7 muscle set-ups x 7 load cases)
on one core. Model building (geometry, cable derivation) is timed separately from the solves.
Prints one JSON object. Target: solves < 5 s. Usage::

    python benchmarks/bench_l2s1.py [--repeat 1]
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

from lumbar.experiments import l2s1  # noqa: E402
from lumbar.inputs.characteristics import CHARACTERISTIC_SETS, load_characteristic_set  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    geo = load_geometry("default", levels=list(l2s1.LEVELS))
    cables = l2s1.derive_cables()
    models = {s: l2s1.build_l2s1(geo, load_characteristic_set(s), cables) for s in CHARACTERISTIC_SETS}
    t_build = time.perf_counter() - t0
    best, per_set, conv = float("inf"), {}, 0
    for _ in range(a.repeat):
        t = time.perf_counter()
        per, conv = {}, 0
        for s, sp in models.items():
            ts = time.perf_counter()
            sol = l2s1.solve_scenarios(sp)
            per[s] = round(time.perf_counter() - ts, 3)
            conv += int(sol.converged.sum())
        dt = time.perf_counter() - t
        if dt < best:
            best, per_set = dt, per
    print(json.dumps({"benchmark": "l2s1_294_equilibria", "scenarios": 294, "converged": conv,
                      "solve_seconds": round(best, 3), "per_set_seconds": per_set,
                      "build_seconds": round(t_build, 3), "target_seconds": 5.0,
                      "threads": os.environ.get("OMP_NUM_THREADS")}, indent=2))


if __name__ == "__main__":
    main()
