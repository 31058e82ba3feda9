"""Calibration stage, rule posterior_figure: the prior and posterior 90 % interval of every calibrated parameter, with
the posterior draws' interval (inputs: roles calibration.posterior and calibration.sampling of the stage manifests;
lumbar.plots.posterior).

By hand: python workflow/scripts/posterior_figure.py posterior_figure --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import pandas as pd  # noqa: E402
from lumbar.plots.posterior import plot_prior_posterior  # noqa: E402


def main(snakemake, log):
    table = pd.read_csv(snakemake.input.posterior)
    plot_prior_posterior(table, snakemake.output[0], pd.read_csv(snakemake.input.sampling))
    log.info("wrote %s (%d parameters)", snakemake.output[0], len(table))


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
