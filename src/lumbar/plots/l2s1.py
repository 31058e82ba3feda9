"""Figures of the L2-S1 IDP experiment (paper 1, Table 5 and Fig. 7; lumbar.experiments.l2s1): the check/cross
grid of the outliers and the IDP per muscle set-up and load case (matplotlib object API, no pyplot)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..experiments.l2s1 import scenario_grid
from ..inputs.io import atomic_writer, subplots
from ..inputs.tables import LOAD_CASES, MUSCLE_SETUPS

SETUP_LABELS = {"none": "without muscles", "multifidus_caudal": "multifidus to caudal",
                "iliocostalis_longissimus": "iliocostalis longissimus", "psoas_vertebral_bodies": "psoas vertebrae",
                "psoas_transverse_processes": "psoas transversus", "multifidus_cranial": "multifidus to cranial",
                "all": "all muscles"}


def _kind_note(syn):
    kinds = sorted(set(syn["data_kind"].astype(str)))
    return ("reference = SURROGATE (virtual specimens, not measured)" if kinds == ["surrogate"]
            else f"reference kind: {', '.join(kinds)}")


def plot_table5_grid(syn: pd.DataFrame, path):
    """Check/cross grid: rows = set-up x load case, columns = characteristic sets."""
    sets = list(dict.fromkeys(syn["set"]))
    rows = scenario_grid()
    cells = {(s, ms, lc): (bool(c), bool(o)) for s, ms, lc, c, o in
             syn[["set", "muscle_setup", "load_case", "converged", "outlier"]].itertuples(index=False)}
    fig, ax = subplots(figsize=(2.0 + 1.3 * len(sets), 14), dpi=100)
    # the marks lie inside the axes: left out of tight_layout's pass over every artist (the same bytes)
    for j, s in enumerate(sets):
        for i, (ms, lc) in enumerate(rows):
            conv, out = cells[(s, ms, lc)]
            if not conv:
                ax.text(j, i, "n.c.", color="#d62728", ha="center", va="center", fontsize=8, fontweight="bold",
                        in_layout=False)
            elif out:
                ax.text(j, i, "\u2717", color="#d62728", ha="center", va="center", fontsize=12, in_layout=False)
            else:
                ax.text(j, i, "\u2713", color="#2ca02c", ha="center", va="center", fontsize=12, in_layout=False)
    ax.set_xlim(-0.5, len(sets) - 0.5)
    ax.set_ylim(len(rows) - 0.5, -0.5)
    ax.set_xticks(range(len(sets)))
    ax.set_xticklabels([f"{s}\n{int(syn[syn['set'] == s]['outlier'].sum())}/49" for s in sets], fontsize=8)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([f"{SETUP_LABELS[ms]} | {lc.replace('_', ' ')}" for ms, lc in rows], fontsize=7)
    for k in range(1, len(MUSCLE_SETUPS)):
        ax.axhline(k * len(LOAD_CASES) - 0.5, color="grey", lw=0.5)
    ax.set_title(f"Table 5: L4-L5 IDP within mean +- SD (\u2713) or outlier (\u2717, n.c. = no equilibrium)\n"
                 f"{_kind_note(syn)}", fontsize=9)
    fig.tight_layout()
    with atomic_writer(path, "wb") as fh:
        fig.savefig(fh, format="png", metadata={"Software": None})


def plot_fig7(syn: pd.DataFrame, path, set_name="calibrated"):
    """Fig. 7: bars = reference mean with SD, circles = simulated IDP, red crosses = outliers."""

    if set_name not in set(syn["set"]):
        set_name = syn["set"].iloc[0]
    d = syn[syn["set"] == set_name].set_index(["muscle_setup", "load_case"])
    import matplotlib  # noqa: PLC0415 - matplotlib only where a figure is drawn

    colours = matplotlib.colormaps["tab10"].colors
    fig, ax = subplots(figsize=(16, 6), dpi=100)
    w = 0.8 / len(MUSCLE_SETUPS)
    for k, ms in enumerate(MUSCLE_SETUPS):
        xs = np.arange(len(LOAD_CASES)) - 0.4 + (k + 0.5) * w
        r = d.loc[[(ms, lc) for lc in LOAD_CASES]]
        ax.bar(xs, r["idp_mean_mpa"], w * 0.9, color=colours[k], alpha=0.55, label=SETUP_LABELS[ms],
               yerr=r["idp_sd_mpa"], error_kw=dict(ecolor="black", capsize=2, lw=0.8))
        ax.scatter(xs, r["idp_sim_mpa"], s=28, facecolor="none", edgecolor=colours[k], linewidth=1.5, zorder=3)
        out = r["outlier"].to_numpy(bool)
        sim = np.where(np.isfinite(r["idp_sim_mpa"]), r["idp_sim_mpa"], 0.0)
        ax.scatter(xs[out], sim[out], marker="x", color="red", s=40, zorder=4)
    ax.set_xticks(range(len(LOAD_CASES)))
    ax.set_xticklabels([lc.replace("_", " ") for lc in LOAD_CASES])
    ax.set_ylabel("L4-L5 IDP [MPa]")
    n_out = int(d["outlier"].sum())
    ax.set_title(f"Fig. 7: L4-L5 IDP, set '{set_name}': bars mean +- SD ({_kind_note(syn)}); circles model; "
                 f"red crosses {n_out} outliers", fontsize=10)
    ax.legend(fontsize=8, ncol=4)
    fig.tight_layout()
    with atomic_writer(path, "wb") as fh:
        fig.savefig(fh, format="png", metadata={"Software": None})
