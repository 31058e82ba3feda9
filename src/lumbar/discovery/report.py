"""The outputs of one discovery (discovery.json, scenarios.csv, figures, the report section in markdown),
:func:`run` (read, build, discover, write) and the summary of the discoveries on real data."""
from __future__ import annotations

import json
import logging
from pathlib import Path

import pandas as pd

from ..experiments import effects as fx
from ..inputs.io import write_json_atomic, write_table_atomic, write_text_atomic
from ..plots.discovery import fmt, plot_before_after, plot_disagreement_map, plot_ranking
from .detect import DiscoveryInputError, discovery_settings, read_measured
from .fit import discover
from .problems import build_problem
from .text import jsonable

log = logging.getLogger(__name__)


def section_markdown(out, measured_path) -> str:
    r = out["result"]
    pe = r["parameter_estimate"]
    lines = [f"## Discrepancy discovery: `{measured_path}`", "",
             f"Experiment **{r['experiment']}**, {r['n_scenarios']} scenarios. Residuals are scaled by the "
             f"measurement uncertainty of each row (z, in standard errors); the gap is the RMS of z.", "",
             f"- gap before: **{r['gap_before']:.2f}** (RMS {r['gap_before_rms']:.3g} {r['unit']})",
             f"- named effect: **{r['named_effect'] or 'none'}**"
             + (f", {pe['parameter']} = {pe['value']:.4g} {pe['unit']}"
                + (" (AT ITS BOUND)" if pe["at_bound"] else "")
                + f"; p = {r['p_value']:.3g}; confidence among the candidates {r['confidence']:.2f}"
                if r["named_effect"] else ""),
             f"- gap after: **{r['gap_after']:.2f}** (RMS {r['gap_after_rms']:.3g} {r['unit']}; "
             f"reduction {100 * r['gap_reduction']:.0f}%)"
             + (" - still above the threshold min_gap" if r["gap_after_above_threshold"] else ""),
             f"- decision: {r['decision']}", "",
             "| rank | effect | LR statistic | p (adjusted) | estimate | at bound | CV RMS z |",
             "|---|---|---|---|---|---|---|"]
    k = 0
    for m, v in r["ranking"]:
        if m == "none":
            continue
        k += 1
        est = r["estimates"].get(m)
        est_s = "" if est is None else f"{est:.4g} {fx.EFFECTS[m].unit}"
        lines.append(f"| {k} | {m} | {v:.2f} | {fmt(r['p_values_adjusted'].get(m))} | {est_s} | "
                     f"{'yes' if r['at_bound'].get(m) else 'no'} | {fmt(r['cv_rms_z'].get(m), '.2f')} |")
    ns = r["identifiability"]["non_separable"]
    lines += ["", f"Identifiability (correlation of sensitivity vectors; pairs with |r| >= "
                  f"{r['identifiability']['max_correlation']:g} are not separable on this experiment):"]
    if not ns:
        lines.append("every pair of candidates is separable here.")
    for it in ns:
        nxt = "; ".join(", ".join(f"{kk}={vv}" for kk, vv in m.items() if kk not in ("separation_z",
                                                                                      "already_measured"))
                        + f" (separation {m['separation_z']:.2g} z" + (", already measured" if m["already_measured"]
                                                                       else "") + ")"
                        for m in it["measure_next"])
        lines.append(f"- {it['pair'][0]} vs {it['pair'][1]}: r = {fmt(it['correlation'], '.3f')}"
                     + (f" ({it['note']})" if it.get("note") else "") + f"; measure next: {nxt or 'n/a'}")
    lines += ["", "![disagreement map](disagreement_map.png)", "", "![ranking](ranking.png)", "",
              "![before/after](before_after.png)", "",
              f"Naming rule: {json.dumps(r['margins'])}; criterion: {r['criterion']}.", ""]
    return "\n".join(lines)


def write_outputs(out, out_dir, measured_path):
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    res = dict(out["result"])
    log.info("discovery on %s took %.2f s (%d forward batches)", measured_path, res.pop("seconds", float("nan")),
             res["forward_batches"])      # timings stay out of the result files (deterministic outputs)
    res["measured"] = str(measured_path)
    res = jsonable(res)
    write_json_atomic(res, d / "discovery.json", allow_nan=True)
    write_table_atomic(out["scenarios"], d / "scenarios.csv")
    plot_disagreement_map(out, d / "disagreement_map.png")
    plot_ranking(out, d / "ranking.png")
    plot_before_after(out, d / "before_after.png")
    write_text_atomic(section_markdown(out, measured_path), d / "section.md")
    return d / "discovery.json"


def run(config, measured, out_dir, segment_loads=None, idp_model=None, cache=None):
    """Read, build the problem, discover, write outputs; returns the result dict."""
    exp, df = read_measured(measured)
    prob = build_problem(exp, df, config, segment_loads=segment_loads, idp_model=idp_model)
    if not prob.candidates:
        raise DiscoveryInputError(f"no candidate effect of config discovery.effects acts on experiment {exp}; "
                                  f"effects acting there: {fx.effect_names(exp)}")
    out = discover(prob, discovery_settings(config), cache=cache)
    write_outputs(out, out_dir, measured)
    return out["result"]


# ------------------------------------------------------------------ real measurements (issue 15)
REAL_DATA_COLUMNS = ("dataset", "n_rows", "gap_before", "named_effect", "p_value", "estimate", "gap_after", "note")


def real_data_summary(paths) -> pd.DataFrame:
    """One row per discovery run on real measurements (its ``discovery.json``): dataset (= run directory),
    n_rows, gap_before, named_effect ("" = nothing named), p_value, estimate (with unit), gap_after and a note
    (the reason when nothing is named; bounds and residual gaps flagged)."""
    rows = []
    for p in paths:
        p = Path(p)
        r = json.loads(p.read_text())
        pe = r.get("parameter_estimate")
        notes = []
        if r.get("named_effect"):
            notes.append(f"named at p = {r['p_value']:.3g} (alpha {r['margins']['alpha']:g}); confidence among the "
                         f"candidates {r['confidence']:.2f}")
            if pe and pe.get("at_bound"):
                notes.append("estimate AT ITS BOUND")
            if r.get("gap_after_above_threshold"):
                notes.append("gap after the refit still above min_gap: more is missing")
        else:
            notes.append(r["decision"])
            if r.get("best_candidate") and not r.get("too_few_rows"):
                notes.append(f"best candidate {r['best_candidate']} (estimate {r['best_candidate_estimate']:.4g})")
        ns = (r.get("identifiability") or {}).get("non_separable") or []
        if ns:
            notes.append("not separable here: " + ", ".join(" vs ".join(i["pair"]) for i in ns))
        rows.append({"dataset": p.parent.name, "n_rows": r["n_scenarios"], "gap_before": r["gap_before"],
                     "named_effect": r.get("named_effect") or "", "p_value": r.get("p_value"),
                     "estimate": f"{pe['value']:.4g} {pe['unit']}" if pe else "",
                     "gap_after": r["gap_after"], "note": "; ".join(notes) + f" [{r.get('measured', '')}]"})
    return pd.DataFrame(rows, columns=list(REAL_DATA_COLUMNS))
