"""Figures of the load-sharing experiment (lumbar.experiments.load_sharing): the moment-rotation curves of the
unit per characteristic set and the moment carried by each structure (matplotlib object API, no pyplot)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..experiments.load_sharing import CURVE_DIRECTIONS, JUMP_DEG, moment_shares
from ..inputs.io import save_figure_atomic, subplots

STRUCTURE_COLOURS = {"disc": "#4c72b0", "facet_left": "#dd8452", "facet_right": "#c44e52", "ALL": "#55a868",
                     "PLL": "#8172b3", "FL": "#937860", "CL": "#da8bc3", "ITL": "#8c8c8c", "ISL": "#ccb974",
                     "SSL": "#64b5cd"}


def plot_curves(curves_by_set: dict, reference: pd.DataFrame | None, path, stage="intact",
                bands: pd.DataFrame | None = None) -> None:
    """Moment-rotation curves of the unit (one panel per direction, one line per characteristic set) with the
    in-vitro ROM at 10 N*m (and its +-25 % band) of ``reference`` (columns direction, value_deg) and, shaded, the
    calibrated set's 90 % posterior band of the rotation (``bands``: the role load_sharing.bands of the stage manifests)."""
    fig, axes = subplots(2, 3, figsize=(12, 7))
    ref = {} if reference is None else dict(zip(reference["direction"], reference["value_deg"]))
    for ax, d in zip(axes.ravel(), CURVE_DIRECTIONS):
        if bands is not None and len(bands) and stage == "intact":
            b = bands[(bands["direction"] == d) & (bands["quantity"] == "rotation_deg")].sort_values("moment_nm")
            if len(b):
                ax.fill_between(b["moment_nm"], b["low90"], b["high90"], color="C0", alpha=0.18, lw=0,
                                label="calibrated, 90 % posterior band")
        for i, (name, cv) in enumerate(curves_by_set.items()):
            g = cv[(cv["stage"] == stage) & (cv["direction"] == d)].sort_values("moment_nm")
            lw = 2.2 if name == "calibrated" else 1.0
            ax.plot(g["moment_nm"], g["rotation_deg"], "-", lw=lw, color="C0" if name == "calibrated" else f"C{i + 1}",
                    label=name)
            jumps = g[g["jump"]]
            if len(jumps):
                ax.plot(jumps["moment_nm"], jumps["rotation_deg"], "rx", ms=8)
        base = d.replace("_right", "").replace("_left", "")
        if base in ref:
            v = ref[base]
            ax.errorbar([10.0], [v], yerr=[[0.25 * v], [0.25 * v]], fmt="ks", capsize=4, ms=6,
                        label="Yamamoto 1989 (+-25 %)")
        ax.set_title(d.replace("_", " "), fontsize=10)
        ax.set_xlabel("moment [N*m]")
        ax.set_ylabel("rotation [deg]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Moment-rotation curves, {stage} unit (continuation in 0.25 N*m steps; x = a jump >= {JUMP_DEG} deg)",
                 fontsize=10)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)


def plot_shares(curves: pd.DataFrame, path, stage="intact", title="") -> None:
    """Stacked moment shares of the structures against the applied moment, one panel per direction: the structures
    that resist the applied moment stacked upward from 0, those that act with it (a pre-tensioned ligament on the
    side that shortens, a facet pushed by the pre-stress) stacked downward, so that the upper stack minus the lower
    one is the applied moment (the dashed line) at every step."""
    sh = moment_shares(curves[(curves["stage"] == stage) & (curves["moment_nm"] > 0)])
    fig, axes = subplots(2, 3, figsize=(12, 7), sharey=True)
    for ax, d in zip(axes.ravel(), CURVE_DIRECTIONS):
        g = sh[sh["direction"] == d]
        wide = g.pivot_table(index="moment_nm", columns="structure", values="moment_resisted_nm", sort=False)
        M = wide.index.to_numpy(float)
        for part in (wide.clip(lower=0.0), wide.clip(upper=0.0)):
            base = np.zeros(len(M))
            for lab in part.columns:
                v = part[lab].to_numpy(float)
                if np.nanmax(np.abs(v), initial=0.0) < 0.02:
                    continue
                ax.fill_between(M, base, base + v, color=STRUCTURE_COLOURS.get(lab, "0.6"), alpha=0.85,
                                label=lab.replace("_", " "), lw=0)
                base = base + v
        ax.axhline(0.0, color="k", lw=0.6)
        ax.plot(M, M, "k--", lw=0.8)
        ax.set_title(d.replace("_", " "), fontsize=10)
        ax.set_xlabel("applied moment [N*m]")
        ax.set_ylabel("moment carried [N*m]")
        ax.grid(alpha=0.3)
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 10), fontsize=8)
    fig.suptitle(title or f"Moment carried by each structure, {stage} unit (below 0: acting with the applied "
                 "moment; upper stack minus lower stack = the applied moment, dashed)", fontsize=10)
    fig.tight_layout(rect=(0, 0.06, 1, 0.96))
    save_figure_atomic(fig, path, dpi=110)
