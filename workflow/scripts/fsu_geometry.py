"""Geometry stage, rule fsu_geometry: the summary table of the configured geometry (one row per level).

By hand: python workflow/scripts/fsu_geometry.py fsu_geometry --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.geometry import summary_table  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    g = snakemake.params.geometry
    geo = load_configured(g)
    log.info("geometry %r: vertebrae %s, levels %s", geo.name, sorted(geo.vertebrae), sorted(geo.levels))
    table = summary_table(geo)
    write_table_atomic(table, snakemake.output[0])
    log.info("wrote %d levels x %d columns to %s", *table.shape, snakemake.output[0])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
