"""Geometry stage: rules fsu_geometry (table) and fig1_l4l5_model (3D figure).

By hand: python workflow/scripts/geometry.py fsu_geometry --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

snakemake, log = _common.start(globals())

from lumbar.geometry import load_geometry, summary_table  # noqa: E402  (after logging, so import warnings are logged)


def load(geometry_cfg):
    kind = geometry_cfg["kind"]
    if kind == "visible_human":
        return load_geometry(kind, path=geometry_cfg["path"])
    return load_geometry(kind)


geo = load(snakemake.params.geometry)
log.info("geometry %r: vertebrae %s, levels %s", geo.name, sorted(geo.vertebrae), sorted(geo.levels))

if snakemake.rule == "fsu_geometry":
    from lumbar.inputs.io import write_table_atomic

    table = summary_table(geo)
    write_table_atomic(table, snakemake.output[0])
    log.info("wrote %d levels x %d columns to %s", *table.shape, snakemake.output[0])
elif snakemake.rule == "fig1_l4l5_model":
    from lumbar.plots.render import render_fsu

    used = render_fsu(geo, snakemake.params.level, snakemake.output[0], backend=snakemake.params.backend)
    log.info("rendered %s with %s to %s", snakemake.params.level, used, snakemake.output[0])
else:
    raise SystemExit(f"geometry.py does not implement rule {snakemake.rule!r}")
