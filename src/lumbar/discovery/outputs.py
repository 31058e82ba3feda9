"""The outputs of one discovery (discovery.json, scenarios.csv, figures, the report section in markdown),
:func:`run` (read, build, discover, write) and the summary of the discoveries on real data; the paper-style report
that shows them is the package :mod:`lumbar.report`."""
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


def _nuisance_lines(r) -> list[str]:
    """The nuisance comparison of a discovery as markdown: the specimen-mean prediction and every nuisance family
    (refit, LR statistic against the specimen mean, p-value, gap), the test of the best candidate against them."""
    sm = r.get("specimen_mean") or {}
    specimens = (r.get("null_model") or {}).get("kind") == "virtual_specimens"
    lines = ["", "Nuisance explanations (fitted beside the candidates; null hypothesis: " + _null_text(r) + "):", "",
             "| explanation | refit | LR statistic | p | gap | equivalent candidates |", "|---|---|---|---|---|---|",
             f"| nominal model | - | - | {fmt(sm.get('p_fit')) + ' (fit)' if not specimens else '-'} | "
             f"{fmt(r['gap_before'], '.2f')} | |"]
    if specimens:
        lines.append(f"| specimen-mean shift | mean of the virtual specimens | 0 | {fmt(sm.get('p_fit'))} (fit) | "
                     f"{fmt(sm.get('gap'), '.2f')} | |")
    for name, v in (r.get("nuisance") or {}).items():
        lines.append(f"| {name} | {v['description']} | {fmt(v['lr_statistic'], '.2f')} | {fmt(v['p_value'])} | "
                     f"{fmt(v['gap'], '.2f')} | {', '.join(v['equivalent_candidates'])} |")
    nt = r.get("nuisance_test") or {}
    if nt.get("candidate"):
        lines += ["", f"Best candidate {nt['candidate']} against '{nt['against']}' (the best explanation it is not "
                      f"equivalent to{': ' + ', '.join(nt['equivalent_nuisance']) + ' excluded' if nt['equivalent_nuisance'] else ''}"
                      f"): p = {fmt(nt['p_value'])}; adequacy of its refit p = "
                      f"{fmt((r.get('adequacy_p') or {}).get('best_candidate'))}."]
    return lines


def _null_text(r) -> str:
    nm = r.get("null_model") or {}
    if nm.get("kind") == "virtual_specimens":
        return (f"the nominal model with specimen variation: the table's specimens drawn from {nm['specimens']} "
                f"virtual specimens per null table, measurement noise {nm['noise_additive_sd']:.3g} {nm['unit']} + "
                f"{100 * nm['noise_relative_sd']:.1f} % fitted from the table's spread")
    return "no specimens in this experiment: the nominal model plus Gaussian noise"


def section_markdown(out, measured_path) -> str:
    r = out["result"]
    pe = r["parameter_estimate"]
    lines = [f"## Discrepancy discovery: `{measured_path}`", "",
             f"Experiment **{r['experiment']}**, {r['n_scenarios']} scenarios. Residuals are scaled by the "
             f"measurement uncertainty of each row (z, in standard errors of the specimen mean); the gap is the RMS "
             f"of z.", "",
             f"- decision: **{r['decision']}**",
             f"- gap before: **{r['gap_before']:.2f}** (RMS {r['gap_before_rms']:.3g} {r['unit']}); against the mean "
             f"of virtual specimens of the nominal model: {fmt(r.get('gap_specimen_mean'), '.2f')}",
             f"- named effect: **{r['named_effect'] or 'none'}**"
             + (f", {pe['parameter']} = {pe['value']:.4g} {pe['unit']}"
                + (" (AT ITS BOUND)" if pe["at_bound"] else "")
                + f"; p = {r['p_value']:.3g}; confidence among the candidates {r['confidence']:.2f}"
                + (f"; on this experiment equivalent to a {' or '.join(r['named_equivalent_to'])} (a cause outside "
                   f"the library with that signature cannot be told apart)" if r.get("named_equivalent_to") else "")
                if r["named_effect"] else ""),
             f"- gap after: **{r['gap_after']:.2f}** (RMS {r['gap_after_rms']:.3g} {r['unit']}; "
             f"reduction {100 * r['gap_reduction']:.0f}%)"
             + (" - still above the threshold min_gap" if r["gap_after_above_threshold"] else ""),
             f"- best nuisance explanation: {r.get('best_nuisance_description')} (gap "
             f"{fmt(r.get('gap_nuisance'), '.2f')})"]
    lines += [f"- why: {x}" for x in r.get("decision_reasons") or []]
    lines += [f"- input warning: {x}" for x in r.get("input_warnings") or []]
    lines += ["", "| rank | effect | LR statistic | p (adjusted) | estimate | at bound | CV RMS z |",
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
    lines += _nuisance_lines(r)
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


# ------------------------------------------------------------------ real measurements
REAL_DATA_COLUMNS = ("dataset", "n_rows", "gap_before", "named_effect", "p_value", "estimate", "gap_after", "decision",
                     "best_nuisance", "nuisance_p_value", "gap_specimen_mean", "gap_nuisance", "note")


def real_data_summary(paths) -> pd.DataFrame:
    """One row per discovery run on real measurements (its ``discovery.json``): dataset (= run directory),
    n_rows, gap_before, named_effect ("" = nothing named), p_value, estimate (with unit), gap_after, the decision
    (named / nuisance / unexplained / nothing named), the nuisance comparison (the best nuisance explanation with its
    refit, its p-value against the specimen mean, the gaps against the specimen mean and after the nuisance refit)
    and a note (the reasons; bounds and residual gaps flagged)."""
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
            notes += list(r.get("decision_reasons") or [])
            if r.get("best_candidate") and not r.get("too_few_rows"):
                notes.append(f"best candidate {r['best_candidate']} (estimate {r['best_candidate_estimate']:.4g})")
        ns = (r.get("identifiability") or {}).get("non_separable") or []
        if ns:
            notes.append("not separable here: " + ", ".join(" vs ".join(i["pair"]) for i in ns))
        bn = r.get("best_nuisance")
        rows.append({"dataset": p.parent.name, "n_rows": r["n_scenarios"], "gap_before": r["gap_before"],
                     "named_effect": r.get("named_effect") or "", "p_value": r.get("p_value"),
                     "estimate": f"{pe['value']:.4g} {pe['unit']}" if pe else "",
                     "gap_after": r["gap_after"], "decision": r.get("decision", ""),
                     "best_nuisance": r.get("best_nuisance_description") or "",
                     "nuisance_p_value": ((r.get("nuisance") or {}).get(bn) or {}).get("p_value"),
                     "gap_specimen_mean": r.get("gap_specimen_mean"), "gap_nuisance": r.get("gap_nuisance"),
                     "note": "; ".join(notes) + f" [{r.get('measured', '')}]"})
    return pd.DataFrame(rows, columns=list(REAL_DATA_COLUMNS))


def benchmark_paragraph(summary: dict) -> str:
    """The benchmark in one paragraph for the report, every number read from ``summary``
    (:func:`lumbar.discovery.power_study.summarise_benchmark`)."""
    s = summary
    lib, ool, nul = s["library_at_benchmark_magnitudes"], s["out_of_library_unnamed"], s["null_p_values"]

    def pct(x):
        return fmt(100 * x, ".0f") + " %" if x is not None else "n/a"

    def ci(v):
        return f"95 % CI {pct(v[0])}-{pct(v[1])}"

    power = {}
    for p in s["power"]:
        power.setdefault(p["effect"], []).append(p)
    curve = "; ".join(f"{e} " + ", ".join(f"{q['power']:.0%} at {q['magnitude']:.3g} {q['unit']}"
                                           for q in sorted(v, key=lambda q: q["magnitude"]))
                      for e, v in sorted(power.items()))
    fails = [k for k, v in s["pass"].items() if v is False]
    return (f"The discrepancy discovery was benchmarked on {s['n_cases']} test fixtures it did not make "
            f"({s['generator']}). Null tables: {s['false_positives']} of {s['n_null']} named an effect "
            f"({pct(s['false_positive_rate'])}, {ci(s['false_positive_rate_95ci'])}; target at most "
            f"{pct(s['targets']['false_positive_rate_max'])}); their p-values spread like a uniform "
            f"distribution (Kolmogorov-Smirnov p = {fmt(nul['ks_p'])} over {nul['n']} nulls, median "
            f"{fmt(nul['median'], '.2f')}). Library effects at their benchmark magnitudes were named correctly in "
            f"{lib['k']} of {lib['n']} cases ({pct(lib['rate'])}, {ci(lib['rate_95ci'])}; target at least "
            f"{pct(s['targets']['library_named_at_benchmark_magnitudes_min'])}), a wrong effect in "
            f"{s['library_wrong_effect_named']} of {s['n_library']} library cases. Out-of-library causes "
            f"(the disc stiffer or softer, a ligament removed, the ROM scaled per direction, the IDP scaled): nothing "
            f"named in {ool['k']} of {ool['n']} ({pct(ool['rate'])}, {ci(ool['rate_95ci'])}; target at least "
            f"{pct(s['targets']['out_of_library_unnamed_min'])}). Probability of naming the planted effect by "
            f"magnitude: {curve}. "
            + (f"Not benchmarked: {'; '.join(f'{k} ({v})' for k, v in sorted(s['not_benchmarked'].items()))}. "
               if s.get("not_benchmarked") else "")
            + ("Every target is met." if s["all_pass"] else f"Targets not met: {', '.join(fails)}."))
