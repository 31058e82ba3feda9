"""Benchmark: L4-L5 equilibria per second in batch mode vs scipy.optimize.root per scenario.

Prints one JSON object. Both engines solve the same scenarios (pure moments 0.5-10 N*m in the four
directions, intact unit, published characteristics) on one core in the same run; the baseline
uses ``scipy.optimize.root(method="hybr")`` with its internal finite-difference Jacobian, started
from the same 0 N*m equilibrium. Usage::

    python benchmarks/bench_fsu.py [--n 1000] [--n-baseline 40] [--geometry default|synthetic]
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import root  # noqa: E402

from lumbar.mechanics import so3  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.experiments.fsu import MAIN_DIRECTIONS, build_fsu, moment_loads  # noqa: E402
from lumbar.mechanics.solve import solve  # noqa: E402


def scenarios(n, seed=0):
    rng = np.random.default_rng(seed)
    dirs = [MAIN_DIRECTIONS[i % 4] for i in range(n)]
    return dirs, rng.uniform(0.5, 10.0, n)


def baseline_one(m, x0, R0, load):
    def fun(q):
        x = x0 + q[:3][None, None]
        R = so3.exp(q[3:][None, None]) @ R0
        Q, _ = m.evaluate(x, R, load[None], jacobian=False)
        return Q[0, 0]
    sol = root(fun, np.zeros(6), method="hybr", options={"xtol": 1e-12})
    return sol.success and np.abs(fun(sol.x)[:3]).max() < 1e-6 and np.abs(fun(sol.x)[3:]).max() < 1e-6


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, default=1000)
    p.add_argument("--n-baseline", type=int, default=40)
    p.add_argument("--geometry", default="default")
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args(argv)
    if a.geometry == "synthetic":
        from lumbar.geometry.synthetic import symmetric_fsu  # noqa: PLC0415 - only the chosen geometry's loader
        geo = symmetric_fsu()
    else:
        from lumbar.geometry import load_geometry  # noqa: PLC0415 - only the chosen geometry's loader
        geo = load_geometry(a.geometry)
    fsu = build_fsu(geo, load_characteristic_set("calibrated"))
    m = fsu.model
    r0 = solve(m, np.zeros((1, m.nb, 6)), load_steps=1)
    dirs, M = scenarios(a.n)
    loads = moment_loads(dirs, M, m.nb)
    x0 = np.repeat(r0.x, a.n, 0)
    R0 = np.repeat(r0.R, a.n, 0)
    best = np.inf
    for _ in range(a.repeat):
        t = time.perf_counter()
        res = solve(m, loads, x0=x0, R0=R0)
        best = min(best, time.perf_counter() - t)
    n_conv = int(res.converged.sum())
    nb_ = min(a.n_baseline, a.n)
    t = time.perf_counter()
    ok = [baseline_one(m, r0.x, r0.R, loads[i]) for i in range(nb_)]
    tb = time.perf_counter() - t
    eps_batch = n_conv / best
    eps_base = sum(ok) / tb if sum(ok) else float("nan")
    out = {
        "benchmark": "fsu_equilibria", "geometry": geo.name, "n_scenarios": a.n,
        "converged": n_conv, "seconds": round(best, 4),
        "equilibria_per_second": round(eps_batch, 1),
        "baseline": "scipy.optimize.root(method='hybr', finite-difference Jacobian) per scenario",
        "baseline_scenarios": nb_, "baseline_converged": int(sum(ok)), "baseline_seconds": round(tb, 4),
        "baseline_equilibria_per_second": round(eps_base, 1),
        "speedup_vs_scipy_root": round(eps_batch / eps_base, 1) if eps_base == eps_base else None,
        "target_equilibria_per_second": 1000,
    }
    print(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    main()
