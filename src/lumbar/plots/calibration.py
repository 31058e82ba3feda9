"""Figures of the calibration (matplotlib object API, no pyplot, no backend switching): the disc torque-angle
fit (Fig. 4 analog) and the calibrated ligament characteristics (Fig. 5 analog), from the tables the calibration
writes (lumbar.experiments.calibration)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..experiments.calibration.disc import eq3
from ..experiments.stepwise_reduction import MAIN_DIRECTIONS
from ..inputs.io import save_figure_atomic, subplots
from ..mechanics.elements.ligament import softplus_force


def data_label(table: pd.DataFrame) -> str:
    """The kinds of data a calibration table was fitted on (its ``data_kind`` column), for a figure's title:
    ``measured``, ``surrogate (SURROGATE reference data)``, ``measured+surrogate (...)``."""
    kinds = sorted(set(table["data_kind"]))
    return "+".join(kinds) + (" (SURROGATE reference data)" if "surrogate" in kinds else "")


def plot_disc_torque_angle(disc_points: pd.DataFrame, table: pd.DataFrame, path, data_label="") -> None:
    """Fig. 4 analog: disc torque vs angle [deg], data points (ROM_mean, M) and the fitted Eq. 3."""
    fig, ax = subplots(figsize=(7, 4.5))
    colours = dict(zip(MAIN_DIRECTIONS, ("C0", "C1", "C2", "C3")))
    for d in MAIN_DIRECTIONS:
        pts = disc_points[disc_points["direction"] == d]
        row = table[table["direction"] == d].iloc[0]
        p = (row["p1_nm"], row["p2_rad3"], row["p3_nm_per_rad"])
        phi = np.linspace(0, max(16.0, pts["rom_deg"].max() * 1.15), 300)
        ax.plot(phi, eq3(np.radians(phi), p), "-", color=colours[d], label=f"{d} (Eq. 3 fit)")
        ax.plot(pts["rom_deg"], pts["moment_nm"], "o--", color=colours[d], mfc="none", lw=0.8)
    ax.set_xlabel("rotation angle [deg]")
    ax.set_ylabel("disc torque [N*m]")
    ax.set_title("Disc torque-angle (stage w/o ALL)" + (f" - data: {data_label}" if data_label else ""), fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=120)


def plot_ligament_characteristics(points: pd.DataFrame, table: pd.DataFrame, path, data_label="") -> None:
    """Fig. 5 analog: per ligament, modelled (strain, force) at the fit stage's solutions and the fitted Eq. 7."""
    fig, axes = subplots(2, 3, figsize=(11, 6.5))
    for ax, k in zip(axes.ravel(), ("ALL", "PLL", "CL", "FL", "ISL", "SSL")):
        row = table[table["ligament"] == k].iloc[0]
        pts = points[points["ligament"] == k] if len(points) else points
        lo = min(-5.0, pts["strain_pct"].min() - 2) if len(pts) else -5.0
        hi = max(25.0, pts["strain_pct"].max() + 2) if len(pts) else 25.0
        eps = np.linspace(lo, hi, 300)
        F, _ = softplus_force(eps, row["a_n"], row["b_pct"], row["c_n"], row["d_pct"])
        ax.plot(eps, F, "-", color="C0", label="Eq. 7 fit (tension-only)")
        for g, gp in pts.groupby("group") if len(pts) else []:
            gp = gp.sort_values("strain_pct")
            ax.plot(gp["strain_pct"], gp["force_n"], "o--", mfc="none", lw=0.6, label=f"{g} (model)")
        ax.set_title(f"{k} (fit on {row['fit_stage']})", fontsize=9)
        ax.set_xlabel("strain [%]")
        ax.set_ylabel("force [N]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    if data_label:
        fig.suptitle(f"Ligament characteristics calibrated on {data_label}", fontsize=10)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
