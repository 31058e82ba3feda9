"""Figures of the validation on real data (lumbar.experiments.validation): the other levels' ROM and curves, and
the scoreboard of every distinct comparison (matplotlib object API, no pyplot)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..experiments.validation import (CONSTRAINT, INDEPENDENT, INTERNAL, ROLE_ORDER, TARGET, condition_label,
                                      distinct_comparisons, sets_label, unit_label)
from ..inputs.io import save_figure_atomic, subplots


def plot_multilevel(rom: pd.DataFrame, curves: pd.DataFrame, path) -> None:
    """Other levels: simulated vs measured ROM at 10 N*m (bars with the +-25 % band) and the flexion-extension
    curves of every level."""
    fig, (a1, a2) = subplots(1, 2, figsize=(12, 4.5))
    labels = [f"{r.level}\n{r.direction.replace('_one_side', '').replace('_', ' ')}" for r in rom.itertuples()]
    xs = np.arange(len(rom))
    meas = rom["measured_deg"].to_numpy(float)
    a1.bar(xs - 0.2, meas, 0.4, color="0.7", label="Yamamoto 1989")
    a1.errorbar(xs - 0.2, meas, yerr=0.25 * meas, fmt="none", ecolor="k", capsize=2, lw=0.8)
    col = ["C2" if w else "C3" for w in rom["within"]]
    a1.bar(xs + 0.2, rom["sim_deg"].to_numpy(float), 0.4, color=col, label="model (green: within 25 %)")
    a1.set_xticks(xs)
    a1.set_xticklabels(labels, fontsize=6, rotation=90)
    a1.set_ylabel("ROM at 10 N*m [deg]")
    a1.legend(fontsize=8)
    a1.set_title(f"Other levels, L4-L5 characteristics unchanged: {int(rom['within'].sum())} of {len(rom)} within 25 %",
                 fontsize=9)
    for i, (lv, g) in enumerate(curves.groupby("level", sort=False)):
        for d, sign, ls in (("flexion", 1, "-"), ("extension", -1, "--")):
            h = g[g["direction"] == d].sort_values("moment_nm")
            a2.plot(sign * h["moment_nm"], sign * h["rotation_deg"], ls, color=f"C{i}", label=lv if d == "flexion" else None)
    a2.axhline(0, color="0.5", lw=0.5)
    a2.axvline(0, color="0.5", lw=0.5)
    a2.set_xlabel("moment [N*m] (flexion +, extension -)")
    a2.set_ylabel("rotation [deg]")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)


def _row_labels(g: pd.DataFrame) -> list[str]:
    return [condition_label(c) for c in g["condition"]]


#: the roles of the two scoreboard figures: the report's first figure (ROM, IDP, anatomy: independent checks and
#: calibration targets) and the internal loads beside it (never fitted, and those the fit holds as constraints)
MAIN_ROLES = (INDEPENDENT, TARGET)
INTERNAL_ROLES = (INTERNAL, CONSTRAINT)


def plot_scoreboard(df: pd.DataFrame, path, roles=None) -> None:
    """The validation scoreboard as one figure: every distinct comparison of ``df`` (a real-data scoreboard,
    see :func:`distinct_comparisons`) as a row: the measured value (black bar) with the interval a simulated
    value must fall in (grey band), the simulated value (green dot within, red cross outside, red "no value"
    where the model gave none). Panels per quantity and unit; independent checks in the left column,
    calibration targets (fit quality, not validation) in the right one. Generic over the rows: a new quantity
    is a new panel."""
    from matplotlib.lines import Line2D  # noqa: PLC0415

    d = distinct_comparisons(df)
    if roles is not None and len(d):
        d = d[d["role"].isin(roles)].reset_index(drop=True)
    roles = [r for r in ROLE_ORDER if (d["role"] == r).any()] if len(d) else []
    roles += [r for r in dict.fromkeys(d.get("role", [])) if r not in roles]
    if not roles:
        fig, ax = subplots(figsize=(7.0, 1.0), dpi=150)
        ax.axis("off")
        ax.text(0.5, 0.5, "no comparison of this kind in this configuration", ha="center", va="center")
        save_figure_atomic(fig, path)
        return
    groups = {r: [(q, g) for q, g in d[d["role"] == r].groupby(["quantity", "unit", "sets"], sort=False)]
              for r in roles}
    row_in, head_in = 0.145, 0.36          # inches per comparison row and per panel (title, axis)
    heights = {r: sum(len(g) * row_in + head_in for _, g in groups[r]) for r in roles}
    H = max(heights.values()) + 0.55
    W = 7.2
    fig, _ = subplots(figsize=(W, H), dpi=200)
    fig.delaxes(fig.axes[0])
    col_w = 1.0 / len(roles)
    # the row labels' share of a column: room for the longest label at 5.6 pt (about 0.04 in per character)
    longest = max((len(lab) for lab in _row_labels(d)), default=0)
    lab_frac = float(np.clip((0.04 * longest + 0.12) / (W * col_w), 0.42, 0.65))
    title = {INDEPENDENT: "Independent checks (validation)", TARGET: "Calibration targets (fit quality)",
             INTERNAL: "Internal loads (never fitted)", CONSTRAINT: "Internal loads (fit constraints)"}
    for ci, role in enumerate(roles):
        w_in, _ = counts_text(d, role)
        fig.text(ci * col_w + 0.01, 1 - 0.12 / H, f"{title.get(role, role)}: {w_in}", fontsize=7.5,
                 fontweight="bold", va="top")
        top = H - 0.42
        for (q, unit, sets), g in groups[role]:
            h = len(g) * row_in
            left = ci * col_w + col_w * lab_frac
            ax = fig.add_axes([left, (top - h - 0.16) / H, col_w * (0.97 - lab_frac), h / H])
            _draw_panel(ax, g)
            fig.text(ci * col_w + 0.01, (top - 0.06) / H, f"{condition_label(q)} [{unit_label(unit)}], {sets_label(sets)}",
                     fontsize=6.6, fontweight="bold", va="top")
            top -= len(g) * row_in + head_in
    handles = [Line2D([], [], color="0.55", lw=5, alpha=0.5, label="acceptance interval"),
               Line2D([], [], color="k", marker="|", ls="", ms=7, label="measured"),
               Line2D([], [], color="#1a9641", marker="o", ls="", ms=4, label="simulated, within"),
               Line2D([], [], color="#d7191c", marker="X", ls="", ms=5, label="simulated, outside")]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=6.5, frameon=False,
               bbox_to_anchor=(0.5, 0.0))
    save_figure_atomic(fig, path)


def counts_text(d: pd.DataFrame, role: str) -> tuple[str, int]:
    g = d[d["role"] == role]
    return f"{int(g['within'].sum())} of {len(g)} within", len(g)


def _draw_panel(ax, g: pd.DataFrame) -> None:
    n = len(g)
    y = np.arange(n)[::-1].astype(float)
    vals = np.concatenate([g["measured"].to_numpy(float), g["sim"].to_numpy(float), g["band_low"].to_numpy(float),
                           g["band_high"].to_numpy(float)] +
                          [g[c].to_numpy(float) for c in ("sim_band_low", "sim_band_high") if c in g])
    vals = vals[np.isfinite(vals)]
    lo, hi = (float(vals.min()), float(vals.max())) if len(vals) else (0.0, 1.0)
    pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.1
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_ylim(-0.7, n - 0.3)
    for yi, r in zip(y, g.itertuples(index=False)):
        if np.isfinite(r.band_low) and np.isfinite(r.band_high):
            ax.plot([r.band_low, r.band_high], [yi, yi], color="0.55", lw=4.5, alpha=0.45, solid_capstyle="butt")
        ax.plot([r.measured], [yi], marker="|", color="k", ms=7, mew=1.2)
        blo, bhi = getattr(r, "sim_band_low", np.nan), getattr(r, "sim_band_high", np.nan)
        if np.isfinite(blo) and np.isfinite(bhi):       # the simulated value's 90 % posterior band
            ax.plot([blo, bhi], [yi, yi], color="#1a9641" if r.within else "#d7191c", lw=1.1)
        if np.isfinite(r.sim):
            if r.within:
                ax.plot([r.sim], [yi], marker="o", color="#1a9641", ms=3.6, ls="")
            else:
                ax.plot([r.sim], [yi], marker="X", color="#d7191c", ms=4.6, ls="")
        else:                          # no simulated value (no equilibrium): said inside the panel, at its left
            ax.text(lo - pad, yi, " no simulated value", color="#d7191c", fontsize=5.5, va="center", ha="left")
    ax.set_yticks(y)
    ax.set_yticklabels(_row_labels(g), fontsize=5.6)
    ax.tick_params(axis="x", labelsize=5.5, length=2, pad=1)
    ax.tick_params(axis="y", length=0, pad=2)
    ax.grid(axis="x", color="0.9", lw=0.5)
    ax.set_axisbelow(True)
    for s in ("top", "right"):
        ax.spines[s].set_visible(False)
