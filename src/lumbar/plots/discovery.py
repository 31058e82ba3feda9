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
                    # dark text on pale cells, white on saturated ones; inside the axes, so left out of the
                    # constrained layout's pass (same bytes, the heatmaps 10-15 % faster)
                    col = "white" if abs(M[i, j]) > 0.6 * vmax else "black"
                    ax.text(j, i, f"{M[i, j]:.1f}", ha="center", va="center", fontsize=6, color=col, in_layout=False)
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
    """LR statistics of the candidates (green: named) and of the nuisance explanations (blue), against the
    specimen-mean prediction, with the 99 % quantile of the null tables' largest candidate statistic."""
    r = out["result"]
    items = [(m, v, "candidate") for m, v in r["ranking"] if m != "none"]
    items += [(f"[nuisance] {m}", v["lr_statistic"], "nuisance") for m, v in (r.get("nuisance") or {}).items()]
    items = sorted(items, key=lambda t: t[1])
    fig, ax = subplots(figsize=(8.5, 1.8 + 0.4 * max(1, len(items))), constrained_layout=True)
    names = [m for m, _, _ in items]
    vals = [v for _, v, _ in items]
    colors = ["tab:green" if m == r["named_effect"] else "tab:blue" if k == "nuisance" else "0.6"
              for m, _, k in items]
    ax.barh(names, vals, color=colors)
    q = r.get("null_lr_quantiles") or {}
    if q.get("0.99") is not None:
        ax.axvline(q["0.99"], color="k", ls="--", lw=0.8, label="99 % of the null tables (max over candidates)")
        ax.legend(fontsize=7, loc="lower right")
    for i, (m, v, k) in enumerate(items):
        if k == "candidate":
            pa = (r.get("p_values_adjusted") or {}).get(m)
            est = r["estimates"].get(m)
            est_s = "nan" if est is None else f"{est:.3g} {fx.EFFECTS[m].unit}"
            txt = (f"p={pa:.3g}" if pa is not None else "p: not tested") + f", est={est_s}"
        else:
            nu = r["nuisance"][m.split("] ", 1)[1]]
            txt = f"p={fmt(nu['p_value'])}, {nu['description']}"
        ax.text(max(v, 0), i, " " + txt[:70], va="center", fontsize=7)
    ax.set_xlabel("LR statistic against the specimen mean, (chi2_0 - chi2) / c  [-]")
    if r["named_effect"]:
        t = f"named: {r['named_effect']} (p = {r['p_value']:.3g}, confidence {r['confidence']:.2f})"
    elif r.get("too_few_rows"):
        t = f"nothing named: too few rows ({r['n_scenarios']})"
    else:
        t = f"{r['decision']} (best candidate {r['best_candidate']}, p = {fmt(r.get('p_value'))})"
    ax.set_title(t[:120], fontsize=9)
    ax.set_xlim(0, max(vals + [1.0]) * 1.8)
    _save(fig, path)


def plot_before_after(out, path):
    """z before (nominal model) and after the explanation the decision gives: the named effect's refit, else the
    best nuisance refit (or the specimen-mean prediction), so a table nothing in the library explains shows what
    a nuisance does with it."""
    scen, p, r = out["scenarios"], out["problem"], out["result"]
    rows, cols, M0 = _pivot(scen, p, "z_before")
    vmax = max(3.0, float(np.nanpercentile(np.abs(M0), 95))) if np.isfinite(M0).any() else 3.0
    w, h = _map_size(rows, cols)
    if r["named_effect"]:
        col, label = "z_after", (f"after adding {r['named_effect']}: gap {r['gap_after']:.2f} "
                                 f"(RMS {r['gap_after_rms']:.3g} {p.unit})")
    elif r.get("too_few_rows") or "z_nuisance" not in scen:
        fig, ax = subplots(figsize=(w, h + 0.6), constrained_layout=True)
        im = _heat(ax, rows, cols, M0, vmax, f"nothing named, the model is unchanged: gap {r['gap_before']:.2f} "
                   f"(RMS {r['gap_before_rms']:.3g} {p.unit})")
        ax.set_xlabel("; ".join(r["decision"].split(": ", 1)[-1].split("; ")[:1])[:110], fontsize=7)
        fig.colorbar(im, ax=ax, label="z (standard errors)")
        _save(fig, path)
        return
    else:
        col = "z_nuisance"
        label = (f"{r['decision']} - refit of the best nuisance explanation, {r['best_nuisance_description']}: "
                 f"gap {fmt(r.get('gap_nuisance'), '.2f')} (no library effect named)")
    _, _, M1 = _pivot(scen, p, col)
    fig, axes = subplots(2, 1, figsize=(w, 2 * h + 0.6), constrained_layout=True)
    _heat(axes[0], rows, cols, M0, vmax, f"before (nominal model): gap {r['gap_before']:.2f} (RMS "
                                         f"{r['gap_before_rms']:.3g} {p.unit})")
    im = _heat(axes[1], rows, cols, M1, vmax, label[:160])
    fig.colorbar(im, ax=axes, label="z (standard errors)")
    _save(fig, path)


def plot_benchmark(bench: pd.DataFrame, summary: dict, path):
    """The benchmark: outcomes per category (null, library, out of library), the power curve (probability of naming
    the planted effect vs its magnitude relative to the smallest benchmark magnitude, with 95 % intervals), and the
    null p-values against the uniform distribution."""
    fig, axes = subplots(1, 3, figsize=(16, 5.0), constrained_layout=True)
    ax = axes[0]
    cats = ["no_effect", "library", "out_of_library"]
    kinds = ["named (correct)", "named (wrong)", "nuisance", "unexplained", "nothing named"]
    colors = ["tab:green", "tab:red", "tab:blue", "tab:orange", "0.7"]
    dec = bench.get("decision", pd.Series([""] * len(bench))).astype(str)
    counts = np.zeros((len(cats), len(kinds)))
    for i, cat in enumerate(cats):
        g = bench["category"] == cat if "category" in bench else bench["hidden_effect"].eq("none") == (cat == "no_effect")
        named = bench["named_effect"] != "none"
        ok = bench["correct"].astype(bool)
        counts[i] = [(g & named & ok).sum(), (g & named & ~ok).sum(), (g & ~named & dec.str.startswith("nuisance")).sum(),
                     (g & ~named & dec.str.startswith("unexplained")).sum(),
                     (g & ~named & ~dec.str.startswith(("nuisance", "unexplained"))).sum()]
    left = np.zeros(len(cats))
    for j, (k, c) in enumerate(zip(kinds, colors)):
        ax.barh(cats, counts[:, j], left=left, color=c, label=k)
        left += counts[:, j]
    ax.legend(fontsize=7, loc="lower right")
    ax.set_xlabel("cases")
    ci = summary["false_positive_rate_95ci"]
    lib, ool = summary["library_at_benchmark_magnitudes"], summary["out_of_library_unnamed"]
    ax.set_title(f"nulls named: {summary['false_positives']}/{summary['n_null']} (95 % CI {fmt(ci[0], '.0%')}-"
                 f"{fmt(ci[1], '.0%')}); library at m1/m2 named: {lib['k']}/{lib['n']};\nout of library left "
                 f"unnamed: {ool['k']}/{ool['n']}", fontsize=9)
    ax = axes[1]
    pw = summary["power"]
    for i, e in enumerate(sorted({p["effect"] for p in pw})):
        ps = sorted([p for p in pw if p["effect"] == e], key=lambda p: p["magnitude"])
        x = [p["relative_magnitude"] for p in ps]
        y = [p["power"] for p in ps]
        lo = [p["power"] - p["power_95ci"][0] for p in ps]
        hi = [p["power_95ci"][1] - p["power"] for p in ps]
        ax.errorbar(x, y, yerr=[lo, hi], fmt="o-", capsize=2, label=f"{e} ({ps[0]['experiment']})", color=f"C{i}")
    ax.axhline(summary["targets"]["library_named_at_benchmark_magnitudes_min"], color="k", ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("magnitude / smallest benchmark magnitude [-]")
    ax.set_ylabel("probability of naming the planted effect [-]")
    ax.set_ylim(-0.05, 1.05)
    ax.legend(fontsize=6)
    ax.set_title("power curve per effect (95 % Clopper-Pearson intervals)", fontsize=9)
    ax = axes[2]
    nul = bench[(bench["category"] == "no_effect") if "category" in bench else bench["hidden_effect"].eq("none")]
    pv = np.sort(nul["p_value"].to_numpy(float))
    pv = pv[np.isfinite(pv)]
    if len(pv):
        ax.plot((np.arange(len(pv)) + 0.5) / len(pv), pv, "o", ms=3)
    ax.plot([0, 1], [0, 1], "k--", lw=0.8)
    ks = summary["null_p_values"]
    ax.set_xlabel("uniform quantile [-]")
    ax.set_ylabel("p-value of the null tables (sorted) [-]")
    ax.set_title(f"null p-values vs uniform: KS p = {fmt(ks['ks_p'])} (n = {ks['n']})", fontsize=9)
    _save(fig, path)
