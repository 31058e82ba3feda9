"""Figure of the OpenSim export's check (matplotlib object API, no pyplot, no backend switching): each exported
model's range of motion in OpenSim against the project's (lumbar.experiments.export_opensim.check_table)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..inputs.io import save_figure_atomic, subplots

STYLES = {"detailed": ("o", "C0", "detailed unit (facets, ligaments, disc)"),
          "detailed_no_facets": ("s", "C2", "detailed unit without facets"),
          "reduced": ("^", "C3", "reduced joint (one bushing)")}


def check_figure(table: pd.DataFrame, path) -> Path:
    """OpenSim's ROM against the project's for every level, direction and moment: the detailed unit with and without
    facets (left) and the reduced joint against the detailed unit with +-10 % shaded (right)."""
    fig, axes = subplots(1, 2, figsize=(9.0, 4.2), constrained_layout=True)
    ok = table[table["status"] == "ok"]
    top = float(np.nanmax(ok[["lumbar_deg", "opensim_deg"]].to_numpy())) * 1.08 if len(ok) else 1.0
    for ax, variants, title in ((axes[0], ("detailed", "detailed_no_facets"), "Detailed unit in OpenSim"),
                                (axes[1], ("reduced",), "Reduced joint against the detailed unit")):
        ax.plot([0, top], [0, top], color="0.4", lw=0.8, label="identity")
        if variants == ("reduced",):
            ax.fill_between([0, top], [0, 0.9 * top], [0, 1.1 * top], color="0.88", label="+-10 %")
        for v in variants:
            g = ok[ok["variant"] == v]
            mk, col, lab = STYLES[v]
            ax.scatter(g["lumbar_deg"], g["opensim_deg"], marker=mk, s=22, edgecolors=col, label=lab,
                       facecolors="none" if v == "detailed_no_facets" else col)
        ax.set(xlim=(0, top), ylim=(0, top), xlabel="ROM, lumbar's solver [deg]", ylabel="ROM, OpenSim 4.6 [deg]",
               title=title)
        ax.set_aspect("equal")
        ax.legend(loc="upper left", fontsize=8, frameon=False)
    if not len(ok):
        fig.text(0.5, 0.5, "OpenSim check not run: " + str(table["status"].iloc[0] if len(table) else "no models"),
                 ha="center", fontsize=9)
    return save_figure_atomic(fig, path, dpi=150)
