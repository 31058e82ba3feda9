"""Figures of the muscle-driven model (paper 2; lumbar.muscles.muscle_model), matplotlib object API (no pyplot, no
backend switching): the in-vivo validation of the L4-L5 IDP (Fig. 3 analog), the IDP against each varied muscle
parameter per muscle-group scope (sensitivity study) and the Sobol indices with their bootstrap intervals."""
from __future__ import annotations

import matplotlib
import numpy as np
import pandas as pd

from ..inputs.io import save_figure_atomic, subplots

#: as every figure of the muscle model was saved (the format's time stamps are left out by save_figure_atomic)
DPI = 150

#: axis label of each varied parameter (the columns ``parameter`` of sensitivity_idp.csv and sobol_indices.csv)
UNITS = {"ssl_um": "SSL [um]", "k_n_per_cm2": "K [N/cm2]", "in_situ_sl_um": "in-situ SL [um]",
         "spt_n_per_cm2": "SpT [N/cm2]", "pennation_deg": "pennation [deg]"}

POSTURE_TITLES = {"standing": "upright standing", "flexion": "36 deg flexion"}


def plot_in_vivo_validation(validation: pd.DataFrame, metrics: dict, path) -> None:
    """L4-L5 IDP per activity, model (compressive-force part and sagittal-moment part stacked) beside in vivo
    (Wilke et al.), a red star over an activity whose posture did not converge; the title gives R2 and n of
    ``metrics`` (role muscle_model.metrics of the stage manifests). ``validation``: role muscle_model.validation."""
    val2 = validation
    fig, ax = subplots(figsize=(6.5, 4))
    xs = np.arange(len(val2))
    ax.bar(xs - 0.2, val2["idp_force_mpa"], 0.4, color="#4c72b0", label="model: compressive force part")
    ax.bar(xs - 0.2, val2["idp_moment_mpa"], 0.4, bottom=val2["idp_force_mpa"], color="#8fb0d9",
           label="model: sagittal moment part")
    ax.bar(xs + 0.2, val2["idp_in_vivo_mpa"], 0.4, color="#555555", label="in vivo (Wilke et al.)")
    starred = False
    for k, ok in enumerate(val2["converged"]):
        if not ok:
            ax.plot(xs[k] - 0.2, val2["idp_sim_mpa"].iloc[k] + 0.05, "r*", ms=12, clip_on=False,
                    label=None if starred else "not converged (excluded from R2)")
            starred = True
    ax.set_ylim(0, 1.2 * max(val2["idp_sim_mpa"].max(), val2["idp_in_vivo_mpa"].max()) + 0.1)
    ax.set_xticks(xs, [a.replace("_", "\n") for a in val2["activity"]], fontsize=8)
    ax.set_ylabel("L4-L5 IDP [MPa]")
    r2 = metrics["r2"]
    ax.set_title(f"L4-L5 IDP, model vs in vivo (R2 = {r2:.2f}, n = {metrics['n']})" if r2 is not None
                 else "L4-L5 IDP, model vs in vivo (R2 undefined: < 3 converged)", fontsize=10)
    ax.legend(fontsize=7)
    save_figure_atomic(fig, path, dpi=DPI)


def plot_sensitivity(table: pd.DataFrame, parameter: str, scopes, postures, path) -> None:
    """L4-L5 IDP against the values of ``parameter`` (rows of the table of role muscle_model.sensitivity), one panel per fixed
    SSL and posture, bars per muscle-group scope (``scopes``, in this order): the compressive-force part solid, the
    sagittal-moment part hatched, the baseline dashed; a red star over a posture not reached, an open circle over a
    reached posture whose optimum is not certified."""
    d = table[table["parameter"] == parameter]
    scopes, posts = list(scopes), list(postures)
    ssls = [x for x in d["ssl_um"].fillna(-1).unique()]
    unit = UNITS[parameter].split("[")[-1].rstrip("]")
    nrow = max(len(ssls) * len(posts), 1)
    fig, axes = subplots(nrow, 1, figsize=(8.5, 0.6 + 2.5 * nrow), layout="constrained")
    axes = np.asarray(axes, dtype=object).reshape(nrow, 1)
    viridis = matplotlib.colormaps["viridis"]
    fig.suptitle(f"L4-L5 IDP vs {UNITS[parameter]} per muscle-group scope. Bars: solid = compressive-force part, "
                 "hatched = sagittal-moment part;\ndashed line: baseline; red star: posture not reached; "
                 "open circle: reached, optimum not certified (KKT)", fontsize=8)
    r = 0
    for sv in ssls:
        for post in posts:
            ax = axes[r, 0]
            r += 1
            dd = d[(d["ssl_um"].fillna(-1) == sv) & (d["posture"] == post)]
            vals = sorted(dd["value"].unique())
            width = 0.8 / max(len(vals), 1)
            top = 0.0
            for j, v in enumerate(vals):
                for si, sc in enumerate(scopes):
                    row = dd[(dd["value"] == v) & (dd["group_scope"] == sc)]
                    if row.empty:
                        continue
                    row = row.iloc[0]
                    xpos = si + (j - (len(vals) - 1) / 2) * width
                    ax.bar(xpos, row["idp_force_mpa"], width * 0.9, color=viridis(j / max(len(vals) - 1, 1)),
                           label=f"{v:g} {unit}" if si == 0 else None)
                    ax.bar(xpos, row["idp_moment_mpa"], width * 0.9, bottom=row["idp_force_mpa"], color="none",
                           edgecolor="k", hatch="//", lw=0.4)
                    y = max(row["idp_mpa"], 0.0)
                    top = max(top, y)
                    if not row["reached"]:
                        ax.plot(xpos, y + 0.05, "r*", ms=9, clip_on=False)
                    elif not row.get("certified", row["converged"]):
                        ax.plot(xpos, y + 0.05, "o", ms=5, mfc="none", mec="0.4", clip_on=False)
            b = dd["baseline_idp_mpa"].iloc[0] if len(dd) else np.nan
            if np.isfinite(b):
                ax.axhline(b, color="k", lw=1, ls="--", label="baseline")
                top = max(top, b)
            ax.set_ylim(0, 1.15 * top + 0.12)
            ax.set_xticks(range(len(scopes)), scopes)
            ax.set_xlabel("muscle groups with the changed parameter", fontsize=7)
            ax.set_ylabel("L4-L5 IDP [MPa]")
            ax.set_title(f"{post}" + (f", SSL fixed at {sv:g} um" if sv != -1 else ""), fontsize=9, loc="left")
            ax.legend(fontsize=7, title=UNITS[parameter], title_fontsize=7, loc="upper left",
                      bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    save_figure_atomic(fig, path, dpi=DPI)


def plot_sobol(df: pd.DataFrame, path) -> None:
    """S1 and ST per parameter with their bootstrap 95 % intervals (whiskers), one panel per posture; the panel
    title gives the method (PCE degree, model solves, leave-one-out Q2). Indices and intervals lie in [0, 1].
    ``df``: the table of role muscle_model.sobol (stage manifests)."""
    posts = list(dict.fromkeys(df["posture"]))
    fig, axes = subplots(1, len(posts), figsize=(4.6 * len(posts), 4.2), sharey=True, layout="constrained")
    axes = np.asarray(axes, dtype=object).reshape(1, len(posts))
    for ax, post in zip(axes[0], posts):
        d = df[df["posture"] == post]
        xs = np.arange(len(d))
        for off, key, lab, col in ((-0.2, "S1", "first-order index S1", "#4c72b0"),
                                   (0.2, "ST", "total index ST", "#dd8452")):
            v = d[key].to_numpy(float)
            lo, hi = d[f"{key}_lo"].to_numpy(float), d[f"{key}_hi"].to_numpy(float)
            ax.bar(xs + off, np.nan_to_num(v), 0.4, color=col, label=lab)
            ax.errorbar(xs + off, np.nan_to_num(v), yerr=[np.clip(np.nan_to_num(v - lo), 0, None),
                                                          np.clip(np.nan_to_num(hi - v), 0, None)],
                        fmt="none", ecolor="k", lw=0.8, capsize=2)
        ax.set_ylim(0, 1.05)
        ax.set_xticks(xs, [UNITS.get(q, q) for q in d["parameter"]], rotation=30, ha="right", fontsize=8)
        r = d.iloc[0]
        q2 = (f"{r['q2_loo']:.3f}" if np.isfinite(r["q2_loo"]) else "n/a") + ("" if r["fit_ok"] else " (poor fit)")
        ax.set_title(f"{POSTURE_TITLES.get(post, post)}: PCE degree {int(r['degree'])}, {int(r['n_train'])} model "
                     f"solves, Q2_loo = {q2}\n{int(r['n_failed'])} not reached (left out), {int(r['n_uncertified'])} "
                     f"not certified; top S1 interval width {r['top_s1_width']:.3f}", fontsize=8)
    axes[0, 0].set_ylabel("Sobol index of L4-L5 IDP [-]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=7,
               title="whiskers: bootstrap 95 % interval", title_fontsize=7)
    save_figure_atomic(fig, path, dpi=DPI)
