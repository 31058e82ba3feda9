"""Stepwise-reduction stage, rule fig6_rom_stepwise_reduction: Fig. 6 analog, the ROM per stage of the calibrated set
(else the first set) against the reference (lumbar.plots.stepwise_reduction).

By hand: python workflow/scripts/fig6_rom_stepwise_reduction.py fig6_rom_stepwise_reduction \
    --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.plots.stepwise_reduction import plot_rom_stepwise_reduction  # noqa: E402


def main(snakemake, log):
    syn = pd.read_csv(snakemake.input[0])
    set_name = "calibrated" if "calibrated" in set(syn["set"]) else str(syn["set"].iloc[0])
    plot_rom_stepwise_reduction(syn, snakemake.output[0], set_name)
    log.info("wrote %s", snakemake.output[0])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
