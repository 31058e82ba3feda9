"""Benchmark: time per discrepancy-discovery run (lumbar.discovery) on one core.

On TEST FIXTURES from virtual specimens (lumbar.discovery.power_study, generator virtual_specimens) of the default
configuration, with the null hypothesis drawn from the bank of virtual specimens (``discovery.null_specimens``), the
nuisance explanations, the candidate-versus-nuisance test and the identifiability step included:

* ROM: one discovery on a 160-scenario stepwise-reduction fixture with the nominal/coarse-grid batch and the null
  bank cached (what a benchmark job, or a second table of the same experiment, pays), against the baseline measured
  in the same run: the same discovery paying the coarse-grid batch and building the bank. Target < 10 s.
* IDP: one discovery on a 49-scenario in-vitro IDP fixture with the nominal L2-S1 model and the null bank cached,
  against the same discovery paying the nominal L2-S1 solve and the bank. Target < 3 s.

The bank builds are reported on their own (the workflow makes them once, rule discovery_specimen_bank). Prints one
JSON object, with the load average of the machine during the run. Usage::

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

from lumbar import discovery as D  # noqa: E402
from lumbar.discovery import problems as discovery_problems  # noqa: E402
from lumbar.discovery import specimens  # noqa: E402
from lumbar.inputs.config import load_config  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _case(experiment, effect, magnitude, seed):
    cat = "null" if effect == "none" else "library"
    return next(pd.DataFrame([{"experiment": experiment, "category": cat, "hidden_effect": effect,
                               "magnitude": magnitude, "magnitude_label": "m1", "seed": seed}]).itertuples(index=False))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args(argv)
    load0 = os.getloadavg()
    cfg = load_config(ROOT / "config" / "config.yaml")
    cfg["characteristics"]["data_dir"] = str(ROOT / cfg["characteristics"]["data_dir"])
    cfg["discovery"]["benchmark"]["fixture_specimens"] = 8      # the fixtures' own specimens: not timed
    s = D.discovery_settings(cfg)
    t0 = time.perf_counter()
    D.fsu_variants_from_config(cfg)
    t_build = time.perf_counter() - t0
    rc = _case("stepwise_rom", "ligament_prestrain", 0.02, 1)
    rom = D.make_hidden_effect_dataset(cfg, "stepwise_rom", rc.hidden_effect, rc.magnitude, rc.seed,
                                       specimens=D.FixtureSpecimens(cfg, pd.DataFrame([rc._asdict()])), case=rc)
    # ROM baseline: the coarse-grid batch and the null bank paid by this discovery
    t = time.perf_counter()
    prob = D.build_problem("stepwise_rom", rom, cfg)
    t_rom_bank = time.perf_counter() - t
    cache = {}
    r = D.discover(prob, s, cache=cache)["result"]
    rom_base = time.perf_counter() - t
    named = {"rom_uncached": r["named_effect"]}
    # IDP baseline: the nominal L2-S1 solve and the null bank paid by this discovery
    ic = _case("idp_invitro", "idp_moment_term", 0.036e6, 2)
    discovery_problems._IDP_MODEL_CACHE.clear()
    t = time.perf_counter()
    model = D.idp_model_table(cfg)
    t_idp_model = time.perf_counter() - t
    idp = D.make_hidden_effect_dataset(cfg, "idp_invitro", ic.hidden_effect, ic.magnitude, ic.seed, idp_model=model,
                                       specimens=D.FixtureSpecimens(cfg, pd.DataFrame([ic._asdict()])), case=ic)
    discovery_problems._IDP_MODEL_CACHE.clear()
    t = time.perf_counter()
    p = D.build_problem("idp_invitro", idp, cfg)
    t_idp_bank = time.perf_counter() - t - t_idp_model
    r = D.discover(p, s)["result"]
    idp_base = time.perf_counter() - t
    named["idp_uncached"] = r["named_effect"]
    best = {"idp_cached": np.inf, "rom_cached": np.inf}
    for _ in range(a.repeat):
        t = time.perf_counter()
        r = D.discover(D.build_problem("idp_invitro", idp, cfg), s)["result"]     # model and bank cached
        best["idp_cached"] = min(best["idp_cached"], time.perf_counter() - t)
        named["idp_cached"] = r["named_effect"]
        t = time.perf_counter()
        r = D.discover(D.build_problem("stepwise_rom", rom, cfg), s, cache=cache)["result"]
        best["rom_cached"] = min(best["rom_cached"], time.perf_counter() - t)
        named["rom_cached"] = r["named_effect"]
    print(json.dumps({
        "benchmark": "discover_time_per_run", "rom_scenarios": len(rom), "idp_scenarios": len(idp),
        "n_bootstrap": s["n_bootstrap"], "null_specimens": s["null_specimens"],
        "idp_seconds": round(best["idp_cached"], 3), "idp_baseline_uncached_seconds": round(idp_base, 3),
        "idp_speedup_vs_baseline": round(idp_base / best["idp_cached"], 1), "idp_target_seconds": 3.0,
        "idp_pass": bool(best["idp_cached"] < 3.0), "idp_nominal_model_seconds": round(t_idp_model, 3),
        "idp_bank_seconds": round(t_idp_bank, 3),
        "rom_seconds": round(best["rom_cached"], 3), "rom_baseline_uncached_seconds": round(rom_base, 3),
        "rom_speedup_vs_baseline": round(rom_base / best["rom_cached"], 2), "rom_target_seconds": 10.0,
        "rom_pass": bool(best["rom_cached"] < 10.0), "rom_bank_seconds": round(t_rom_bank, 3),
        "build_seconds": round(t_build, 3), "named": named, "grid_points": s["grid_points"],
        "threads": os.environ.get("OMP_NUM_THREADS"),
        "load_average_1min_before_after": [round(load0[0], 2), round(os.getloadavg()[0], 2)],
        "cpu_count": os.cpu_count(), "specimen_bank_source": specimens.__name__}, indent=2))


if __name__ == "__main__":
    main()
