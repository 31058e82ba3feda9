"""Geometry stage: rules fsu_geometry (table) and fig1_l4l5_model (3D figure).

By hand: python workflow/scripts/geometry.py fsu_geometry --configfile config/test/config.yaml
"""
import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd

_spec = importlib.util.spec_from_file_location("_common", Path(__file__).resolve().parent / "_common.py")
_common = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_common)

RULES = {
    "fsu_geometry": lambda c: dict(
        output=["results/tables/fsu_geometry.csv"], params=dict(geometry=c["geometry"])),
    "fig1_l4l5_model": lambda c: dict(
        output=["results/figures/fig1_l4l5_model.png"],
        params=dict(geometry=c["geometry"], level=c["fsu"]["level"], backend=c["render"]["backend"])),
}

if "snakemake" not in globals():
    snakemake = _common.stand_in(RULES, __doc__)

log = _common.setup_logging(snakemake)

from lumbar.geometry import load_geometry  # noqa: E402  (after logging, so import warnings are logged)


def load(geometry_cfg):
    kind = geometry_cfg["kind"]
    if kind == "visible_human":
        return load_geometry(kind, path=geometry_cfg["path"])
    return load_geometry(kind)


def geometry_table(geo) -> pd.DataFrame:
    """One row per level: disc centre/normal/CSA/height, facet landmarks, ligament fibres (mm)."""
    rows = []
    for name in sorted(geo.levels):
        lev = geo.levels[name]
        row = {"geometry": geo.name, "level": name, "upper": lev.upper, "lower": lev.lower}
        for ax, c in zip("xyz", lev.disc_centre):
            row[f"disc_centre_{ax}_mm"] = 1e3 * float(c)
        for ax, n in zip("xyz", lev.disc_normal):
            row[f"disc_normal_{ax}"] = float(n)
        row["disc_csa_mm2"] = 1e6 * float(lev.disc_csa)
        row["disc_height_mm"] = 1e3 * float(lev.disc_height)
        row["facet_landmarks_n"] = int(sum(len(f.superior) + len(f.inferior) for f in lev.facets.values()))
        for lig in lev.ligaments:
            length = np.linalg.norm(np.asarray(lig.upper) - np.asarray(lig.lower), axis=1) + np.asarray(lig.extra_length)
            row[f"{lig.name}_n_fibres"] = int(len(length))
            row[f"{lig.name}_mean_length_mm"] = 1e3 * float(length.mean()) if len(length) else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


geo = load(snakemake.params.geometry)
log.info("geometry %r: vertebrae %s, levels %s", geo.name, sorted(geo.vertebrae), sorted(geo.levels))

if snakemake.rule == "fsu_geometry":
    from lumbar.io import write_table_atomic

    table = geometry_table(geo)
    write_table_atomic(table, snakemake.output[0])
    log.info("wrote %d levels x %d columns to %s", *table.shape, snakemake.output[0])
elif snakemake.rule == "fig1_l4l5_model":
    from lumbar.render import render_fsu

    used = render_fsu(geo, snakemake.params.level, snakemake.output[0], backend=snakemake.params.backend)
    log.info("rendered %s with %s to %s", snakemake.params.level, used, snakemake.output[0])
else:
    raise SystemExit(f"geometry.py does not implement rule {snakemake.rule!r}")
