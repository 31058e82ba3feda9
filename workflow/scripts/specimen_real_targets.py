"""Rule specimen_real_targets: the real targets of a specimen calibrated on another unit than L4-L5, Yamamoto et al.
(1989)'s intact ROM of that unit in the experiment-table schema (lumbar.experiments.admissibility.yamamoto_level_targets).

By hand: python workflow/scripts/specimen_real_targets.py specimen_real_targets --configfile my_specimen.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.experiments.admissibility import yamamoto_level_targets  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    table = yamamoto_level_targets(snakemake.params.level, snakemake.input.yamamoto)
    write_table_atomic(table, snakemake.output[0])
    log.info("wrote %d rows of %s (%s) to %s", len(table), snakemake.params.level, snakemake.input.yamamoto,
             snakemake.output[0])


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
