"""Validation stage, rule validation_scoreboard_figure: the figure of the real-data scoreboard (the report's first
figure; lumbar.plots.validation).

By hand: python workflow/scripts/validation_scoreboard_figure.py validation_scoreboard_figure \
    --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.experiments import validation as V  # noqa: E402
from lumbar.plots.validation import INTERNAL_ROLES, MAIN_ROLES, plot_scoreboard  # noqa: E402


def main(snakemake, log):
    table = pd.read_csv(snakemake.input[0])
    plot_scoreboard(table, snakemake.output.scoreboard, roles=MAIN_ROLES)
    plot_scoreboard(table, snakemake.output.internal_loads, roles=INTERNAL_ROLES)
    counts = V.role_counts(V.distinct_comparisons(table))
    log.info("validation scoreboard figure: %d rows, %s", len(table),
             "; ".join(f"{role}: {w} of {n} distinct comparisons within" for role, (w, n) in counts.items()))


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
