"""Benchmark: time per discrepancy-discovery run (lumbar.discover) on one core.

Three runs on hidden-effect TEST FIXTURES of the default configuration: a stepwise-reduction ROM table
(160 scenarios, ligament prestrain hidden; 4 solver candidates x 3 batched forward solves), the same with the
coarse-grid batch cached (what a benchmark job pays per further case), and an in-vitro IDP table (49 scenarios,
3 IDP candidates, from a synthetic L2-S1 model table: no solve). Model building is timed separately.
Prints one JSON object. Usage::

    python benchmarks/bench_discover.py [--repeat 1]
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar import discover as D  # noqa: E402
from lumbar.config import load_config  # noqa: E402
from lumbar.l2s1 import scenario_grid  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def idp_model_fixture():
    """Synthetic nominal L2-S1 table (TEST FIXTURE schema of rule discovery_idp_model)."""
    grid = scenario_grid()
    rng = np.random.default_rng(3)
    F = 150 + 250 * rng.random(len(grid))
    per_n = 1.68 / 1.6e-3
    return pd.DataFrame({"muscle_setup": [g[0] for g in grid], "load_case": [g[1] for g in grid], "converged": True,
                         "idp_mpa": F * per_n / 1e6, "disc_axial_force_n": F,
                         "disc_moment_sagittal_nm": rng.normal(-1.5, 2.0, len(grid)), "idp_per_newton_pa": per_n})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args(argv)
    cfg = load_config(ROOT / "config" / "config.yaml")
    cfg["characteristics"]["data_dir"] = str(ROOT / cfg["characteristics"]["data_dir"])
    s = D.discovery_settings(cfg)
    t0 = time.perf_counter()
    D.fsu_variants_from_config(cfg)
    t_build = time.perf_counter() - t0
    rom = D.make_hidden_effect_dataset(cfg, "stepwise_rom", "ligament_prestrain", 0.03, seed=1)
    model = idp_model_fixture()
    idp = D.make_hidden_effect_dataset(cfg, "idp_invitro", "idp_moment_term", 0.036e6, seed=2, idp_model=model)
    best = {"rom": np.inf, "rom_cached": np.inf, "idp": np.inf}
    named = {}
    for _ in range(a.repeat):
        cache = {}
        for key, df, exp, kw in (("rom", rom, "stepwise_rom", {}), ("rom_cached", rom, "stepwise_rom", {}),
                                 ("idp", idp, "idp_invitro", {"idp_model": model})):
            t = time.perf_counter()
            r = D.discover(D.build_problem(exp, df, cfg, **kw), s, cache=cache)["result"]
            best[key] = min(best[key], time.perf_counter() - t)
            named[key] = r["named_effect"]
    print(json.dumps({"benchmark": "discover_time_per_run", "rom_scenarios": len(rom), "idp_scenarios": len(idp),
                      "rom_seconds": round(best["rom"], 3), "rom_cached_coarse_seconds": round(best["rom_cached"], 3),
                      "idp_seconds": round(best["idp"], 3), "build_seconds": round(t_build, 3),
                      "named": named, "grid_points": s["grid_points"],
                      "threads": os.environ.get("OMP_NUM_THREADS")}, indent=2))


if __name__ == "__main__":
    main()
