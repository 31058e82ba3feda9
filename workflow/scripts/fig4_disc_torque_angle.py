"""Calibration stage, rule fig4_disc_torque_angle: the disc torque-angle fit of the calibration (Fig. 4 analog;
lumbar.plots.calibration).

By hand: python workflow/scripts/fig4_disc_torque_angle.py fig4_disc_torque_angle --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.plots.calibration import data_label, plot_disc_torque_angle  # noqa: E402


def main(snakemake, log):
    pts, tab = pd.read_csv(snakemake.input.points), pd.read_csv(snakemake.input.table)
    plot_disc_torque_angle(pts, tab, snakemake.output[0], data_label=data_label(pts))
    log.info("wrote %s", snakemake.output[0])


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
