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
The MAP fit with its Laplace posterior (the anchoring fit) is timed as such (target < 120 s); ``--mcmc`` adds a short
MCMC on the same objective (emcee, benchmarks/requirements-mcmc.txt) and reports the sampled over the Laplace spread
of every parameter: a check of the linearisation, run once, never in the DAG.
Usage: python benchmarks/bench_calibration.py [--mcmc [--mcmc-steps N]]
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
    steps = int(sys.argv[sys.argv.index("--mcmc-steps") + 1]) if "--mcmc-steps" in sys.argv else 120
    mcmc = mcmc_check(anchor, n_steps=steps, burn=steps // 3) if "--mcmc" in sys.argv else None
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


def mcmc_check(fit, n_walkers=44, n_steps=120, burn=40, seed=7) -> dict:
    """A short MCMC (emcee's affine-invariant ensemble) on the same objective the MAP fit minimises
    (log p = -r.r/2 inside the bounds), started from Laplace draws: per parameter the sampled spread over the Laplace
    spread. Ratios near 1: the Laplace approximation holds; far from 1: the posterior is not Gaussian there (a bound,
    a flat valley) and the bands of that parameter's predictions need sampling."""
    try:
        import emcee  # noqa: PLC0415 - benchmark-only dependency (benchmarks/requirements-mcmc.txt)
    except ImportError:
        return {"skipped": "emcee not installed: pip install -r benchmarks/requirements-mcmc.txt"}
    import numpy as np  # noqa: PLC0415

    post = fit.posterior

    def log_prob(q):
        if np.any(q < post.lower) or np.any(q > post.upper):
            return -np.inf
        r = fit.objective(q)
        return -0.5 * float(r @ r) if np.all(np.isfinite(r)) else -np.inf

    p0 = post.draws(n_walkers, seed=seed)
    sampler = emcee.EnsembleSampler(n_walkers, len(post.names), log_prob)
    t = time.perf_counter()
    sampler.run_mcmc(p0, n_steps, progress=False)
    chain = sampler.get_chain(discard=burn, flat=True)
    ratio = chain.std(axis=0) / post.sd
    return {"walkers": n_walkers, "steps": n_steps, "burn_in": burn, "seconds": round(time.perf_counter() - t, 1),
            "acceptance": round(float(np.mean(sampler.acceptance_fraction)), 3),
            "sd_ratio_mcmc_over_laplace": {n: round(float(v), 3) for n, v in zip(post.names, ratio)},
            "median_sd_ratio": round(float(np.median(ratio)), 3)}


if __name__ == "__main__":
    main()
