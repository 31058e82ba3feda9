"""Figures of the stepwise-reduction experiment (paper 1, Table 4 and Fig. 6; lumbar.experiments.stepwise_reduction):
the check/cross grid of the outliers and the ROM per stage (matplotlib object API, no pyplot)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..experiments.fsu import MAIN_DIRECTIONS, STAGES
from ..inputs.io import save_figure_atomic, subplots


def plot_table4_grid(synopsis: pd.DataFrame, path, sets=None) -> None:
    """Check/cross grid like the paper's Table 4: rows stage x moment, columns set x direction."""

    sets = list(dict.fromkeys(synopsis["set"])) if sets is None else list(sets)
    moments = sorted(synopsis["moment_nm"].unique())
    rows = [(s, M) for s in STAGES for M in moments]
    cols = [(k, d) for k in sets for d in MAIN_DIRECTIONS]
    from matplotlib.patches import Rectangle  # noqa: PLC0415 - matplotlib only where a figure is drawn

    # (outlier, converged) per cell, read once (a .loc per cell cost 0.7 s on the paper's 960 cells)
    cells = {(k, st, d, M): (bool(o), bool(c)) for k, st, d, M, o, c in
             synopsis[["set", "stage", "direction", "moment_nm", "outlier", "converged"]].itertuples(index=False)}
    fig, ax = subplots(figsize=(1.2 + 0.32 * len(cols), 1.2 + 0.22 * len(rows)))
    for i, (st, M) in enumerate(rows):
        for j, (k, d) in enumerate(cols):
            key = (k, st, d, M)
            if key not in cells:
                colour, mark = "0.85", ""
            else:
                out, conv = cells[key]
                colour = "#f4b6b6" if out else "#b9e4b9"
                mark = ("x" if conv else "NC") if out else "v"
            # the cells lie inside the limits set below: add_artist skips add_patch's data-limit update (2 s on
            # 960 cells) and the marks stay out of tight_layout's pass over every artist (the same bytes)
            ax.add_artist(Rectangle((j, i), 1, 1, color=colour, ec="white"))
            ax.text(j + 0.5, i + 0.5, mark, ha="center", va="center", fontsize=6,
                    color="darkred" if mark in ("x", "NC") else "darkgreen", in_layout=False)
    ax.set_xlim(0, len(cols))
    ax.set_ylim(len(rows), 0)
    ax.set_xticks(np.arange(len(cols)) + 0.5)
    ax.set_xticklabels([f"{k}\n{d[0].upper()}" if d == "flexion" else d[0].upper() for k, d in cols], fontsize=6)
    ax.set_yticks(np.arange(len(rows)) + 0.5)
    ax.set_yticklabels([f"{st} {M:g} Nm" for st, M in rows], fontsize=6)
    kinds = "+".join(sorted(set(synopsis["data_kind"])))
    ax.set_title(f"Outliers (x), not converged (NC), within range (v); reference data: {kinds}", fontsize=8)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=130)


def plot_rom_stepwise_reduction(synopsis: pd.DataFrame, path, set_name="calibrated") -> None:
    """Fig. 6 analog: bars = reference mean with min-max whiskers per stage, circles = simulated, red x = outliers."""

    syn = synopsis[synopsis["set"] == set_name]
    moments = sorted(syn["moment_nm"].unique())
    fig, axes = subplots(len(MAIN_DIRECTIONS), 1, figsize=(12, 11), sharex=True)
    import matplotlib  # noqa: PLC0415 - see plot_table4_grid

    colours = matplotlib.colormaps["viridis"](np.linspace(0, 0.95, len(STAGES)))
    width = 0.8 / len(STAGES)
    for ax, d in zip(axes, MAIN_DIRECTIONS):
        for k, st in enumerate(STAGES):
            sub = syn[(syn["direction"] == d) & (syn["stage"] == st)].set_index("moment_nm").reindex(moments)
            x = np.arange(len(moments)) + (k - len(STAGES) / 2 + 0.5) * width
            mean = sub["rom_mean_deg"].to_numpy(float)
            lo = np.where(np.isfinite(sub["rom_min_deg"]), mean - sub["rom_min_deg"], 0)
            hi = np.where(np.isfinite(sub["rom_max_deg"]), sub["rom_max_deg"] - mean, 0)
            hatch = "//" if (sub["data_kind"] == "derived_from_published_fit").any() else None
            ax.bar(x, mean, width, color=colours[k], label=st if d == MAIN_DIRECTIONS[0] else None,
                   hatch=hatch, edgecolor="k", lw=0.3)
            ax.errorbar(x, mean, yerr=[lo, hi], fmt="none", ecolor="k", lw=0.6, capsize=1.5)
            ax.plot(x, sub["rom_sim_deg"], "o", color=colours[k], mec="k", ms=4)
            out = sub["outlier"].astype(bool).to_numpy()
            yo = np.where(np.isfinite(sub["rom_sim_deg"]), sub["rom_sim_deg"], mean)
            ax.plot(x[out], yo[out], "x", color="red", ms=8, mew=2)
        ax.set_ylabel(f"{d}\nROM [deg]")
        ax.grid(axis="y", alpha=0.3)
    axes[-1].set_xticks(np.arange(len(moments)))
    axes[-1].set_xticklabels([f"{M:g} N*m" for M in moments])
    axes[0].legend(ncol=8, fontsize=7, loc="upper left")
    kinds = "+".join(sorted(set(syn["data_kind"])))
    n_out = int(syn["outlier"].sum())
    fig.suptitle(f"Stepwise reduction, set '{set_name}': {n_out} outlier(s) of {len(syn)}; bars: reference "
                 f"({kinds}; hatched = derived from the published Eq. 3 fit, no range)", fontsize=9)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
