"""Figures of the discrepancy discovery (matplotlib object API, no pyplot, no backend switching): the
disagreement map, the ranking of the candidates, before/after the refit, and the hidden-effect benchmark."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..experiments import effects as fx
from ..inputs.io import atomic_writer, subplots


def fmt(v, spec=".3g"):
    """A number for the figures and the report section: ``spec`` format, "n/a" for None and non-finite."""
    return "n/a" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, spec)


# ------------------------------------------------------------------ figures (object API, no pyplot), report section
def _save(fig, path):
    with atomic_writer(path, "wb", encoding=None, newline=None) as f:
        fig.savefig(f, format="png", dpi=110, metadata={"Software": None})


def _col_label(vals, keys):
    return " ".join(f"{v} N*m" if k == "moment_nm" else str(v) for k, v in zip(keys, vals))


def _pivot(scen, problem, col):
    rows = list(dict.fromkeys(scen[problem.row_key].astype(str))) if problem.row_key in scen else ["all"]
    ck = problem.col_keys
    cc = [_col_label(v, ck) for v in scen[ck].astype(str).to_numpy()]
    cols = list(dict.fromkeys(cc))
    M = np.full((len(rows), len(cols)), np.nan)
    rk = scen[problem.row_key].astype(str) if problem.row_key in scen else pd.Series(["all"] * len(scen))
    for r, c, v in zip(rk, cc, scen[col]):
        M[rows.index(r), cols.index(c)] = v
    return rows, cols, M


def _heat(ax, rows, cols, M, vmax, title):
    im = ax.imshow(M, cmap="RdBu_r", vmin=-vmax, vmax=vmax, aspect="auto")
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(rows, fontsize=7)
    ax.set_xticks(range(len(cols)))
    ax.set_xticklabels(cols, fontsize=6, rotation=70, ha="right")
    ax.set_title(title, fontsize=8, wrap=True)
    if M.size <= 200:
        for i in range(M.shape[0]):
            for j in range(M.shape[1]):
                if np.isfinite(M[i, j]):
                    # dark text on pale cells, white on saturated ones
                    col = "white" if abs(M[i, j]) > 0.6 * vmax else "black"
                    ax.text(j, i, f"{M[i, j]:.1f}", ha="center", va="center", fontsize=6, color=col)
    return im


def _map_size(rows, cols):
    return max(6.5, min(16, 2.5 + 0.4 * len(cols))), 2.2 + 0.35 * len(rows)


def plot_disagreement_map(out, path):
    scen, p, r = out["scenarios"], out["problem"], out["result"]
    rows, cols, M = _pivot(scen, p, "z_before")
    vmax = max(3.0, float(np.nanpercentile(np.abs(M), 95))) if np.isfinite(M).any() else 3.0
    fig, ax = subplots(figsize=_map_size(rows, cols), constrained_layout=True)
    im = _heat(ax, rows, cols, M, vmax, f"{p.experiment}: z = (model - measured) / sigma\n"
               f"gap (RMS z) = {r['gap_before']:.2f}; RMS {r['gap_before_rms']:.3g} {p.unit}")
    fig.colorbar(im, ax=ax, label="z (standard errors; + model above measurement)")
    _save(fig, path)


def plot_ranking(out, path):
    r = out["result"]
    items = [(m, v) for m, v in r["ranking"] if m != "none"]
    fig, ax = subplots(figsize=(7.5, 1.6 + 0.4 * max(1, len(items))), constrained_layout=True)
    names = [m for m, _ in items][::-1]
    vals = [v for _, v in items][::-1]
    colors = ["tab:green" if m == r["named_effect"] else "0.6" for m in names]
    ax.barh(names, vals, color=colors)
    q = r.get("null_lr_quantiles") or {}
    if q.get("0.99") is not None:
        ax.axvline(q["0.99"], color="k", ls="--", lw=0.8, label="99 % of the bootstrap null (max over candidates)")
        ax.legend(fontsize=7, loc="lower right")
    for i, m in enumerate(names):
        pa = (r.get("p_values_adjusted") or {}).get(m)
        ps = f"p={pa:.3g}" if pa is not None else "p: not tested"
        est = r["estimates"].get(m)
        est_s = "nan" if est is None else f"{est:.3g} {fx.EFFECTS[m].unit}"
        ax.text(max(vals[i], 0), i, f" {ps}, est={est_s}", va="center", fontsize=7)
    ax.set_xlabel("LR statistic vs no effect, (chi2_none - chi2_effect) / c  [-]")
    if r["named_effect"]:
        t = f"named: {r['named_effect']} (p = {r['p_value']:.3g}, confidence {r['confidence']:.2f})"
    elif r.get("too_few_rows"):
        t = f"nothing named: too few rows ({r['n_scenarios']})"
    else:
        pv = r.get("p_value")
        t = f"nothing named (best {r['best_candidate']}, p = {pv:.3g})" if pv is not None else "nothing named"
    ax.set_title(t, fontsize=9)
    ax.set_xlim(0, max(vals + [1.0]) * 1.6)
    _save(fig, path)


def plot_before_after(out, path):
    scen, p, r = out["scenarios"], out["problem"], out["result"]
    rows, cols, M0 = _pivot(scen, p, "z_before")
    vmax = max(3.0, float(np.nanpercentile(np.abs(M0), 95))) if np.isfinite(M0).any() else 3.0
    w, h = _map_size(rows, cols)
    if not r["named_effect"]:
        # nothing added: one map and the reason (not the same map twice)
        fig, ax = subplots(figsize=(w, h + 0.6), constrained_layout=True)
        im = _heat(ax, rows, cols, M0, vmax, f"nothing named, the model is unchanged: gap {r['gap_before']:.2f} "
                   f"(RMS {r['gap_before_rms']:.3g} {p.unit})")
        ax.set_xlabel("; ".join(r["decision"].split(": ", 1)[-1].split("; ")[:1])[:110], fontsize=7)
        fig.colorbar(im, ax=ax, label="z (standard errors)")
        _save(fig, path)
        return
    _, _, M1 = _pivot(scen, p, "z_after")
    fig, axes = subplots(2, 1, figsize=(w, 2 * h + 0.4), constrained_layout=True)
    _heat(axes[0], rows, cols, M0, vmax, f"before: gap {r['gap_before']:.2f} (RMS {r['gap_before_rms']:.3g} {p.unit})")
    im = _heat(axes[1], rows, cols, M1, vmax, f"after adding {r['named_effect']}: "
               f"gap {r['gap_after']:.2f} (RMS {r['gap_after_rms']:.3g} {p.unit})")
    fig.colorbar(im, ax=axes, label="z (standard errors)")
    _save(fig, path)



def plot_benchmark(bench: pd.DataFrame, summary: dict, path):
    fig, axes = subplots(1, 3, figsize=(15, 4.8), constrained_layout=True)
    labels = sorted(set(bench["hidden_effect"]) | set(bench["named_effect"]))
    C = np.zeros((len(labels), len(labels)))
    for h, n in zip(bench["hidden_effect"], bench["named_effect"]):
        C[labels.index(h), labels.index(n)] += 1
    axes[0].imshow(C, cmap="Greens")
    for i in range(len(labels)):
        for j in range(len(labels)):
            if C[i, j]:
                axes[0].text(j, i, int(C[i, j]), ha="center", va="center", fontsize=8,
                             color="white" if C[i, j] > 0.6 * C.max() else "black")
    axes[0].set_xticks(range(len(labels)))
    axes[0].set_xticklabels(labels, rotation=60, ha="right", fontsize=7)
    axes[0].set_yticks(range(len(labels)))
    axes[0].set_yticklabels(labels, fontsize=7)
    axes[0].set_xlabel("named (count of cases)")
    axes[0].set_ylabel("hidden")
    ci = summary["false_positive_rate_95ci"]
    axes[0].set_title(f"false positives {summary['false_positives']}/{summary['n_null']} nulls\n"
                      f"(rate {fmt(summary['false_positive_rate'], '.0%')}, 95 % CI {fmt(ci[0], '.0%')}-"
                      f"{fmt(ci[1], '.0%')})", fontsize=9)
    pw = summary["power"]
    effs = sorted({p["effect"] for p in pw})
    for i, e in enumerate(effs):
        ps = sorted([p for p in pw if p["effect"] == e], key=lambda p: p["magnitude"])
        mags = [p["magnitude"] / max(q["magnitude"] for q in ps) for p in ps]
        axes[1].plot(mags, [p["power"] for p in ps], "o-", label=e, color=f"C{i}")
    axes[1].axhline(summary["targets"]["power_at_larger_magnitude_min"], color="k", ls="--", lw=0.8)
    axes[1].set_xlabel("magnitude / larger benchmark magnitude [-]")
    axes[1].set_ylabel("detection power (share named correctly) [-]")
    axes[1].set_ylim(-0.05, 1.05)
    axes[1].legend(fontsize=6)
    axes[1].set_title("power per effect and magnitude", fontsize=9)
    for i, e in enumerate(effs):
        ps = sorted([p for p in pw if p["effect"] == e], key=lambda p: p["magnitude"])
        mags = [p["magnitude"] / max(q["magnitude"] for q in ps) for p in ps]
        err = [np.nan if p["median_param_rel_error"] is None else 100 * p["median_param_rel_error"] for p in ps]
        axes[2].plot(mags, err, "o-", label=e, color=f"C{i}")     # None: no correct detection at that magnitude
    axes[2].axhline(20, color="k", ls="--", lw=0.8)
    axes[2].set_xlabel("magnitude / larger benchmark magnitude [-]")
    axes[2].set_ylabel("median |parameter error| of detections [%]")
    axes[2].set_title("parameter error", fontsize=9)
    _save(fig, path)
