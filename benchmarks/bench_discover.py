"""Benchmark: time per discrepancy-discovery run (lumbar.discovery) on one core, with cached nominal solves.

On hidden-effect TEST FIXTURES of the default configuration (decision with the parametric bootstrap,
``discovery.n_bootstrap`` null datasets, and the identifiability step included):

* IDP: one discovery on a 49-scenario in-vitro IDP fixture with the nominal L2-S1 model cached
  (``lumbar.discovery.idp_model_table`` solves it once per process), against the baseline measured in the same
  run: the same discovery paying the nominal L2-S1 solve (what every IDP run cost before). Target < 2 s.
* ROM: one discovery on a 160-scenario stepwise-reduction fixture with the nominal/coarse-grid batch cached (what
  a benchmark job pays per further case), against the uncached run as baseline. Target < 10 s.

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

from lumbar import discovery as D  # noqa: E402
from lumbar.discovery import problems as discovery_problems  # noqa: E402
from lumbar.inputs.config import load_config  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


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
    # IDP baseline: the nominal L2-S1 solve + the discovery (uncached)
    discovery_problems._IDP_MODEL_CACHE.clear()
    t = time.perf_counter()
    model = D.idp_model_table(cfg)
    idp = D.make_hidden_effect_dataset(cfg, "idp_invitro", "idp_moment_term", 0.036e6, seed=2, idp_model=model)
    discovery_problems._IDP_MODEL_CACHE.clear()
    t = time.perf_counter()
    r = D.discover(D.build_problem("idp_invitro", idp, cfg), s)["result"]
    idp_base = time.perf_counter() - t
    best = {"idp_cached": np.inf, "rom_uncached": np.inf, "rom_cached": np.inf}
    named = {"idp_uncached": r["named_effect"]}
    for _ in range(a.repeat):
        t = time.perf_counter()
        r = D.discover(D.build_problem("idp_invitro", idp, cfg), s)["result"]     # nominal model cached
        best["idp_cached"] = min(best["idp_cached"], time.perf_counter() - t)
        named["idp_cached"] = r["named_effect"]
        cache = {}
        for key in ("rom_uncached", "rom_cached"):
            t = time.perf_counter()
            r = D.discover(D.build_problem("stepwise_rom", rom, cfg), s, cache=cache)["result"]
            best[key] = min(best[key], time.perf_counter() - t)
            named[key] = r["named_effect"]
    print(json.dumps({
        "benchmark": "discover_time_per_run", "rom_scenarios": len(rom), "idp_scenarios": len(idp),
        "n_bootstrap": s["n_bootstrap"],
        "idp_seconds": round(best["idp_cached"], 3), "idp_baseline_uncached_seconds": round(idp_base, 3),
        "idp_speedup_vs_baseline": round(idp_base / best["idp_cached"], 1), "idp_target_seconds": 2.0,
        "idp_pass": bool(best["idp_cached"] < 2.0),
        "rom_seconds": round(best["rom_cached"], 3), "rom_baseline_uncached_seconds": round(best["rom_uncached"], 3),
        "rom_speedup_vs_baseline": round(best["rom_uncached"] / best["rom_cached"], 2), "rom_target_seconds": 10.0,
        "rom_pass": bool(best["rom_cached"] < 10.0),
        "build_seconds": round(t_build, 3), "named": named, "grid_points": s["grid_points"],
        "threads": os.environ.get("OMP_NUM_THREADS")}, indent=2))


if __name__ == "__main__":
    main()
