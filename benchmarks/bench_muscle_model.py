"""Benchmark: the muscle redundancy solver on the default study, one core.

Prints one JSON object with, for the workflow's solver settings (``current``) and, measured in the same run on
the same postures, the settings before the speed work (``baseline``: batches of 16 postures, every
line-search step length evaluated at once, IPOPT's polish of an SQP point started with least-squares
multipliers; the Millard-curve inversion fix is in both, it has no switch):

* one cold posture (upright standing from the reference pose, zero activations; SQP + IPOPT certificate,
  no multistart), target < 1 s;
* the warm-started solves of the study (baseline solution of each posture as the start): ``--samples`` Sobol
  samples per posture (standing, flexion; the PCE training design of config/config.yaml) and one sensitivity
  chunk (the SSL sweep: 5 values x 4 scopes x 2 postures), each with the seconds per solve and the reached /
  IPOPT-certified counts;
* the estimate of the whole default sensitivity study + Sobol on 2 cores: per-posture seconds per solve times
  the number of solves of each posture, halved (two jobs at a time), target 300 s; and the ratios
  baseline / current.

The workflow's own job times (Snakemake ``benchmark:``, results/benchmarks/muscle_*) measure the same on the
real DAG. Usage: python benchmarks/bench_muscle_model.py [--samples 64] [--no-baseline]
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from lumbar.muscles import muscle_model as mm  # noqa: E402
from lumbar.muscles import muscle_sensitivity as msens  # noqa: E402

CONFIG = Path(__file__).resolve().parents[1] / "config" / "config.yaml"
SETTINGS = {
    "current": {},                                     # the workflow's (RedundancySolver defaults, config)
    "baseline": {"batch_size": 16, "full_step_first": False, "polish_start": "dual"},
}


def _solver(model, cfg, settings):
    s = mm.make_solver(model, {**cfg["solver"], "multistart": False})
    for k, v in settings.items():
        setattr(s, k, v)
    return s


def _study_solves(cfg) -> dict:
    """Solves per posture of the default study: the sweep (Paramspace chunks of workflow/rules/muscle_model.smk:
    each parameter once, K and in-situ SL also at the interplay SSL) and the Sobol design."""
    sens = cfg["sensitivity"]
    values = sum(len(sens[p]) for p in ("ssl_um", "k_n_per_cm2", "in_situ_sl_um", "spt_n_per_cm2", "pennation_deg"))
    values += len(sens["k_n_per_cm2"]) + len(sens["in_situ_sl_um"])
    per_posture = values * len(sens["scopes"])
    return {p: per_posture + cfg["sobol"]["n_train"] for p in sens["postures"]}


def measure(model, cfg, settings, n_samples, seed):
    solver = _solver(model, cfg, settings)
    t = time.perf_counter()
    stand = mm.solve_postures(model, solver, ["upright_standing"])[0]
    out = {"one_posture_s": round(time.perf_counter() - t, 3), "one_posture_certified": bool(stand.certified)}
    base = dict(zip(mm.POSTURES, mm.solve_postures(model, solver, list(mm.POSTURES.values()))))
    X = msens.sobol_samples(cfg["sobol"]["n_train"], seed)
    per = {}
    for posture in mm.POSTURES:
        t = time.perf_counter()
        d = msens.sobol_evaluate(model, solver, base, X, np.arange(n_samples), posture)
        el = time.perf_counter() - t
        per[posture] = el / n_samples
        out[f"sobol_{posture}"] = {"solves": n_samples, "s_per_solve": round(el / n_samples, 3),
                                   "reached": int(d["reached"].sum()), "certified": int(d["certified"].sum())}
    sens = cfg["sensitivity"]
    rows = msens.sensitivity_rows("ssl_um", None, sens["ssl_um"], sens["scopes"], sens["postures"])
    t = time.perf_counter()
    d = msens.run_sensitivity(model, solver, rows, base)
    el = time.perf_counter() - t
    out["sensitivity_chunk"] = {"solves": len(d), "s_per_solve": round(el / len(d), 3),
                                "reached": int(d["reached"].sum()), "certified": int(d["certified"].sum())}
    n = _study_solves(cfg)
    out["study_estimate_2_cores_s"] = round(sum(per[p] * n[p] for p in n) / 2, 1)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=64, help="Sobol samples per posture (default 64, one batch)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the baseline settings (half the time)")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    cfg = yaml.safe_load(CONFIG.read_text())
    mcfg = cfg["muscle_model"]
    t = time.perf_counter()
    model = mm.LumbarMuscleModel()
    res = {"benchmark": "muscle_model", "model_build_s": round(time.perf_counter() - t, 2),
           "targets": {"one_posture_s": 1.0, "study_estimate_2_cores_s": 300.0},
           "study_solves": _study_solves(mcfg)}
    for name, settings in SETTINGS.items():
        if name == "baseline" and a.no_baseline:
            continue
        res[name] = {"settings": settings or "workflow defaults", **measure(model, mcfg, settings, a.samples,
                                                                           cfg["seed"])}
    if "baseline" in res:
        b, c = res["baseline"], res["current"]
        res["ratio_baseline_over_current"] = {
            "one_posture": round(b["one_posture_s"] / c["one_posture_s"], 2),
            "study_estimate": round(b["study_estimate_2_cores_s"] / c["study_estimate_2_cores_s"], 2)}
    res["meets_targets"] = {"one_posture": res["current"]["one_posture_s"] < 1.0,
                            "study": res["current"]["study_estimate_2_cores_s"] < 300.0}
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
