"""Calibration stage, rule calibration_draws: draws from the calibration's posterior, a short MCMC on the objective
the MAP fit minimises (lumbar.experiments.posterior.sample_posterior; config stepwise_reduction.posterior_draws).

The calibration is run again (lumbar.experiments.calibration.calibrate_configured, as rule calibrate runs it;
deterministic), in a job of its own so that every stage reading the calibrated set starts while the chain runs. Its
MAP must be the one rule calibrate shipped (``posterior.csv``). Writes the kept draws (``posterior_draws.csv``, fit
units) and, per parameter, the sampled against the Laplace spread with the chain's diagnostics
(``posterior_sampling.csv``). A calibration without a posterior (no admissible fit) writes both tables' headers.

By hand: python workflow/scripts/calibration_draws.py calibration_draws --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.experiments import calibration as cal  # noqa: E402
from lumbar.experiments import posterior as P  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    p, i, o = snakemake.params, snakemake.input, snakemake.output
    shipped = pd.read_csv(i.posterior)
    # the settings checked against the shipped posterior's parameters before the calibration is rerun
    settings = P.check_draw_settings(p.sr.get("posterior_draws") or {}, len(shipped))
    if shipped.empty:
        log.info("the calibration has no posterior (no admissible fit): %s and %s hold their headers", o.draws,
                 o.sampling)
        write_table_atomic(pd.DataFrame(columns=["draw"]), o.draws)
        write_table_atomic(pd.DataFrame(columns=list(P.SAMPLING_COLUMNS)), o.sampling)
        return
    res = cal.calibrate_configured(p.geometry, p.fsu, p.solver, p.sr, i.experiment, _common.first(i.derived),
                                   _common.as_list(i.real_targets), i.characteristics,
                                   _common.first(i.generator_fit)).result
    fit = res.info.get("final_fit")
    post, _ = cal.posterior_tables(fit, res.info.get("prior_name", ""))
    cal.check_same_map(shipped, post, i.posterior)
    sample = P.sample_posterior(fit.objective, fit.posterior, **settings)
    table = P.sampling_table(fit.posterior, sample)
    write_table_atomic(P.draws_table(sample), o.draws)
    write_table_atomic(table, o.sampling)
    r = table["sd_ratio_sampled_over_laplace"]
    log.info("posterior draws: %d walkers x %d steps (%d burn-in), acceptance %.2f, autocorrelation %.0f steps, about "
             "%.0f independent samples; %d draws kept; sampled / Laplace spread %.2f-%.2f (median %.2f)",
             sample.walkers, sample.steps, sample.burn_in, sample.acceptance, sample.autocorrelation_steps,
             sample.independent_samples, len(sample.draws), r.min(), r.max(), r.median())
    if sample.independent_samples < len(sample.draws):
        log.warning("the posterior chain holds about %.0f independent samples, fewer than the %d draws kept: raise "
                    "stepwise_reduction.posterior_draws.steps (the bands of the band rules are noisier than their "
                    "draw count says)", sample.independent_samples, len(sample.draws))


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
