"""Calibration stage, rule fig5_ligament_characteristics: the calibrated ligament force-elongation laws (Fig. 5
analog; lumbar.plots.calibration).

By hand: python workflow/scripts/fig5_ligament_characteristics.py fig5_ligament_characteristics \
    --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.plots.calibration import data_label, plot_ligament_characteristics  # noqa: E402


def main(snakemake, log):
    pts, tab = pd.read_csv(snakemake.input.points), pd.read_csv(snakemake.input.table)
    plot_ligament_characteristics(pts, tab, snakemake.output[0], data_label=data_label(tab))
    log.info("wrote %s", snakemake.output[0])


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
