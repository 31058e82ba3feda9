"""Geometry stage, rule fig1_l4l5_model: the 3-D figure of the configured motion segment (Fig. 1 analog;
lumbar.plots.render).

By hand: python workflow/scripts/fig1_l4l5_model.py fig1_l4l5_model --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.plots.render import render_fsu  # noqa: E402


def main(snakemake, log):
    g = snakemake.params.geometry
    geo = load_configured(g)
    log.info("geometry %r: vertebrae %s, levels %s", geo.name, sorted(geo.vertebrae), sorted(geo.levels))
    used = render_fsu(geo, snakemake.params.level, snakemake.output[0], backend=snakemake.params.backend)
    log.info("rendered %s with %s to %s", snakemake.params.level, used, snakemake.output[0])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
