"""Benchmark: the backward calibration with the physical-admissibility fit, its admissibility check, and 960 forward
equilibria (6 sets x 160 scenarios), one core.

Prints one JSON object. The calibration runs as the workflow's default (embedded Visible Human L4-L5; laws on
elongation from the elongation prior; real targets: Yamamoto et al. 1989 intact ROM; step 0 and the final step are
the admissible fit, the final one started from step 0) on a noise-free surrogate of the admissible model (1 virtual
specimen, no variation). The surrogate generator's own anchoring (the same fit, rule stepwise_reduction_surrogate) is
timed separately: the workflow runs it once more before the calibration. Baseline measured in the same run: the
calibration of earlier versions (laws transferred by strain, force scales fitted on the real rows alone, no
admissibility). Targets: the calibration with admissibility under 120 s (the default DAG's two jobs run on 2 cores:
their sum, anchoring + calibration, is reported too), the forward equilibria under 2 s.
The MAP fit with its Laplace posterior (the anchoring fit) is timed as such (target < 120 s); ``--mcmc`` adds a check
of the posterior draws: the DAG's chain (rule calibration_draws, lumbar.experiments.posterior.DRAW_DEFAULTS) against
one ``--mcmc-factor`` (default 4) times as long on the same objective, per parameter the sampled over the Laplace
spread of both and the short over the long chain's spread: how far the DAG's short chain and the Laplace
linearisation are from a better-mixed sample. Run once, never in the DAG.
Usage: python benchmarks/bench_calibration.py [--mcmc [--mcmc-factor K]]
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import dataclasses  # noqa: E402
import sys  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402

from lumbar.experiments import admissibility as ADM  # noqa: E402
from lumbar.experiments.calibration import calibrate, calibration_prior, fit_admissible, fit_real_targets  # noqa: E402
from lumbar.experiments.fsu import build_fsu  # noqa: E402
from lumbar.experiments.stepwise_reduction import (read_experiment_table, reference_table,  # noqa: E402
                                                   simulate_stepwise_reduction)
from lumbar.experiments.virtual_experiment import SpecimenVariation, stepwise_reduction_table  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.inputs import resources  # noqa: E402
from lumbar.inputs.characteristics import CHARACTERISTIC_SETS, load_characteristic_set  # noqa: E402


def main():
    logging.basicConfig(level=logging.ERROR)
    gdir = resources.data_dir() / "geometry" / "visible_human_lss"
    geo = load_geometry("visible_human", path=gdir, levels=["L4-L5"])
    paper = load_characteristic_set("calibrated")
    real = read_experiment_table(resources.data_dir() / "experiments" / "yamamoto1989_intact_rom_original_text.csv")
    prior, _, spreads = calibration_prior(paper, geo, "L4-L5", gdir, "remus2021")
    t = time.perf_counter()
    anchor = fit_admissible(geo, prior, real, published=paper, geometry_path=gdir, prior_spread=spreads)
    t_anchor = time.perf_counter() - t
    factor = int(sys.argv[sys.argv.index("--mcmc-factor") + 1]) if "--mcmc-factor" in sys.argv else 4
    mcmc = mcmc_check(anchor, factor) if "--mcmc" in sys.argv else None
    zero = SpecimenVariation(**{f.name: 0.0 for f in dataclasses.fields(SpecimenVariation)})
    table = stepwise_reduction_table(geo, anchor.charset, 1, n_specimens=1, variation=zero, noise_sd_deg=0.0)
    ref = reference_table(table, real=real)
    start = dict(zip(anchor.parameters["parameter"], anchor.parameters["fit_value"]))
    t = time.perf_counter()
    res = calibrate(geo, ref, initial=paper, family="scaled_published", real_targets=real, transfer="elongation",
                    geometry_path=gdir, anchor_start_values=start, prior="remus2021")
    t_cal = time.perf_counter() - t
    t = time.perf_counter()
    adm, _, _ = ADM.evaluate(geo, res.charset, prior, paper, geometry_path=gdir,
                             fit_parameters=res.info.get("real_fit"))
    t_adm = time.perf_counter() - t
    t = time.perf_counter()
    anchored_old = fit_real_targets(geo, paper, real).charset
    old_table = stepwise_reduction_table(geo, anchored_old, 1, n_specimens=1, variation=zero, noise_sd_deg=0.0)
    calibrate(geo, reference_table(old_table, real=real), initial=paper, family="scaled_published", real_targets=real,
              transfer="strain")
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
        "calibration_wall_time_s": round(t_cal, 2), "calibration_target_s": 120,
        "generator_anchoring_s": round(t_anchor, 2),
        "anchoring_plus_calibration_s": round(t_anchor + t_cal, 2),
        "admissibility_check_s": round(t_adm, 2),
        "admissibility_passed": int(adm["passed"].sum()), "admissibility_criteria": len(adm),
        "baseline_strain_transfer_no_admissibility_s": round(t_base, 2),
        "ratio_to_baseline": round(t_cal / t_base, 3),
        "calibration_evaluations": int(res.summary["n_evaluations"].sum()),
        "forward_equilibria": n, "forward_converged": conv,
        "forward_time_s": round(t_fwd, 3), "forward_target_s": 2.0,
        "map_fit_with_laplace_posterior_s": round(t_anchor, 2), "map_fit_target_s": 120,
        "posterior_parameters": len(anchor.posterior.names) if anchor.posterior is not None else 0,
        "mcmc_check": mcmc,
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
    }, indent=2))


def mcmc_check(fit, factor: int = 4) -> dict:
    """The DAG's posterior chain (:data:`lumbar.experiments.posterior.DRAW_DEFAULTS`) and one ``factor`` times as long
    (burn-in scaled alike) on the objective the MAP fit minimises: per parameter the sampled over the Laplace spread of
    each, and the short over the long chain's spread. Ratios to the Laplace spread far from 1: the posterior is not
    Gaussian there (one-sided constraints inactive at the MAP, bounds); short over long well below 1: the DAG's chain
    has not yet spread along that direction, and its bands are that much too narrow there."""
    import numpy as np  # noqa: PLC0415

    from lumbar.experiments.posterior import DRAW_DEFAULTS, sample_posterior  # noqa: PLC0415

    post = fit.posterior
    out = {}
    for label, k in (("dag_chain", 1), ("long_chain", factor)):
        kw = {**DRAW_DEFAULTS, "steps": DRAW_DEFAULTS["steps"] * k, "burn_in": DRAW_DEFAULTS["burn_in"] * k}
        t = time.perf_counter()
        smp = sample_posterior(fit.objective, post, **kw)
        out[label] = {"walkers": smp.walkers, "steps": smp.steps, "burn_in": smp.burn_in,
                      "seconds": round(time.perf_counter() - t, 1), "acceptance": round(smp.acceptance, 3),
                      "autocorrelation_steps": round(smp.autocorrelation_steps, 1),
                      "independent_samples": round(smp.independent_samples),
                      "sd_ratio_over_laplace": {n: round(float(v), 3)
                                                for n, v in zip(post.names, smp.chain_sd / post.sd)},
                      "_sd": smp.chain_sd}
    short, long_ = out["dag_chain"].pop("_sd"), out["long_chain"].pop("_sd")
    ratio = short / long_
    out["sd_ratio_dag_over_long"] = {n: round(float(v), 3) for n, v in zip(post.names, ratio)}
    out["median_sd_ratio_dag_over_long"] = round(float(np.median(ratio)), 3)
    return out


if __name__ == "__main__":
    main()
