"""Report sections before the results: "Validation on real data" (Tables R1-R4), "Flags" (the warnings of the
workflow's logs), "Summary" (one paragraph per study, read from the result files) and "Methods" (generated from the
configuration). Registered in this order, at the end of the registry (:mod:`lumbar.report` imports this module
first)."""
from __future__ import annotations

import json
from typing import Mapping

import numpy as np

from lumbar.inputs.tables import OUTLIER_COUNT_NAMES

from .document import CHECK, CROSS, Para
from .sections import (
    MAX_WARNINGS,
    NOT_BUILT,
    SET_LABELS,
    flatten,
    mentions_surrogate,
    read_csv,
    reference_text,
    fmt,
    report_section,
)
from lumbar.experiments import validation as V


def scoreboard_section(b):
    """Tables R1 and R2: one row per distinct comparison, independent checks apart from calibration targets."""
    rel = b.out("validation", "scoreboard_table")
    d = b.distinct()
    if d is None:
        b.missing("Validation on real data (validation_real_data.csv)")
        return
    b.doc.add(Para("One row per distinct comparison: rows that several characteristic sets share (the "
                   "disc-only stage, for which every set uses the paper's disc) are shown once, with the "
                   "number of sets. Acceptance interval: the published range, else the tolerance named in "
                   "the CSV's tolerance_rule. The 90 % band of the calibrated unit's value and, in brackets, the "
                   "share of the calibration's posterior draws whose value lies in the acceptance interval: how "
                   "firmly the data behind the calibration place the row on its side. "
                   f"Every row, with its source: {rel}. Agreement with the "
                   "SURROGATE tables further below is a method check, not a validation."))
    titles = {V.INDEPENDENT: ("R1", "Independent checks (validation)"),
              V.TARGET: ("R2", "Calibration targets (fit quality, not validation)"),
              V.INTERNAL: ("R3", "Internal loads, independent checks (judged, never fitted)"),
              V.CONSTRAINT: ("R4", "Internal loads the fit also holds as constraints (not independent)")}
    for role, (w, n) in V.role_counts(d).items():
        g = d[d["role"] == role]
        label, title = titles.get(role, (None, role))
        internal = role in (V.INTERNAL, V.CONSTRAINT)
        rows, last = [], None
        for r in g.itertuples(index=False):
            q = f"{V.condition_label(r.quantity)} [{V.unit_label(r.unit)}]"
            band = (f"{fmt(r.band_low)} to {fmt(r.band_high)}" if np.isfinite(r.band_low) else "")
            sim = fmt(r.sim) if np.isfinite(r.sim) else "no value"
            blo = getattr(r, "sim_band_low", np.nan)
            post = f"{fmt(blo)}-{fmt(r.sim_band_high)}" if np.isfinite(blo) else ""
            pw = float(getattr(r, "p_within_posterior", np.nan))
            post += f" ({pw:.0%})" if post and np.isfinite(pw) else ""
            row = [q if q != last else "", V.condition_label(r.condition), sim, post, fmt(r.measured), band,
                   CHECK if r.within else CROSS, V.sets_label(r.sets)]
            if internal:
                row.insert(5, fmt(V.mean_ratio(r.sim, r.measured), 2))
            rows.append(row)
            last = q
        head = ["quantity [unit]", "condition", "simulated", "90 % band", "measured", "acceptance interval",
                "within", "simulated by"]
        title = f"{title}: {w} of {n} distinct comparisons within"
        if internal:
            head.insert(5, "simulated / measured")
            z = V.zero_floor_count(g)
            if z:
                title += (f"; {z} of them with an acceptance interval down to zero, which a load the model does "
                          "not carry at all would also pass: read the ratio to the measured value")
        b.table_block(title, head, rows, source=rel, label=f"Table {label}" if label else None, marks=True,
                      key_cols=2)
    # after the tables (Tables R1 and R2 stay on one page): the independent checks beside trivial models, and where
    # the judged extension facet force comes from
    nulls = b.null_sentence()
    if nulls:
        b.doc.add(Para(f"{nulls} Every count: {b.out('validation', 'null_models')}."))
    edge = b.facet_edge_sentence()
    if edge:
        b.doc.add(Para("Internal loads (Table R3): " + edge))


def flags_section(b):
    """Every WARNING of the workflow's logs: what a user must act on. Expected outcomes are results in their
    tables (and one summary line in the rule's log), not warnings."""
    warn = b.warnings()
    b.doc.add(Para(
        "A warning in a rule's log is something to act on. Expected outcomes are results in their tables, each "
        "rule's log has one summary line for them: postures the muscles cannot hold (columns reached and "
        "converged of the muscle tables; red stars in the figures), scenarios without equilibrium (converged, "
        "n.c. in the grids), ROM measured from an unstable rest state (rest_state_stable of the stepwise-reduction "
        "tables: the disc-only stage, whose flexion law has negative stiffness about zero), calibration parameters that are not identifiable or end at a bound (columns "
        "identifiable and at_bound of calibration_summary.csv), comparisons outside their acceptance interval "
        "(Tables R1 and R2)."))
    if warn is None:
        b.doc.add(Para(f"Workflow logs: {NOT_BUILT} (no logs directory given to the report).", "note"))
    elif not warn:
        b.doc.add(Para("No warning in the workflow's logs.", "p"))
    else:
        note = (f"First {MAX_WARNINGS} of {len(warn)}; every one is in its rule's log under logs/."
                if len(warn) > MAX_WARNINGS else "")
        b.table_block(f"Warnings in the workflow's logs ({len(warn)})", ["rule log", "warning"],
                      [[name, msg] for name, msg in warn[:MAX_WARNINGS]], note=note, key_cols=0)


def summary(b):
    paras = [
        counts_sentence(b, b.out("stepwise_reduction", "vs_paper"), b.out("stepwise_reduction", "counts"),
                        "Stepwise reduction, forward simulation (Table 4 analog)", b.sr_surrogate),
        counts_sentence(b, b.out("l2s1", "vs_paper"), b.out("l2s1", "counts"),
                        "L2-S1 intradiscal pressure (Table 5 analog)", b.idp_surrogate),
        calibration_sentence(b),
        muscle_sentence(b),
        discrepancy_sentence(b),
    ]
    for p in paras:
        b.doc.add(Para(p, "abstract"))


def counts_sentence(b, rel_vs, rel_counts, what, surrogate):
    rel = rel_vs if b.has(rel_vs) else rel_counts if b.has(rel_counts) else None
    if rel is None:
        return f"{what}: {NOT_BUILT}."
    # the vocabulary of lumbar.inputs.tables.VS_PAPER_COLUMNS; an outlier-count table (no vs-paper table built)
    # has no paper columns, Table 5's names its counts outliers / scenarios (lumbar.experiments.l2s1.outlier_counts)
    df = read_csv(b.path(rel)).rename(columns=OUTLIER_COUNT_NAMES)
    ours, scen = "n_outliers", ("n_scenarios" if "n_scenarios" in df.columns else None)
    paper = "paper_n_outliers" if "paper_n_outliers" in df.columns else None
    paper_scen = "paper_n_scenarios" if "paper_n_scenarios" in df.columns else None
    parts = []
    for _, r in df.iterrows():
        s = f"{SET_LABELS.get(r['set'], r['set'])} {fmt(r[ours])} of {fmt(r[scen])}" if scen else \
            f"{SET_LABELS.get(r['set'], r['set'])} {fmt(r[ours])}"
        if paper and fmt(r[paper]) != "":
            ps = f" of {fmt(r[paper_scen])}" if paper_scen and fmt(r[paper_scen]) else ""
            s += f" (paper: {fmt(r[paper])}{ps})"
        parts.append(s)
    ref = ("SURROGATE reference (virtual specimens; a method check, i.e. a round trip, not a reproduction of "
           "the paper's counts)") if surrogate else "the measured reference table"
    real_o, real_n = (c if c in df.columns else None for c in ("n_outliers_real", "n_scenarios_real"))
    if real_o and real_n and surrogate:
        parts_real = [f"{SET_LABELS.get(r['set'], r['set'])} {fmt(r[real_o])} of {fmt(r[real_n])}"
                      for _, r in df.iterrows() if fmt(r[real_n]) not in ("", "0")]
        if parts_real:
            ref += "; outliers among the rows with a real (measured or published-fit) reference: " + \
                "; ".join(parts_real)
    paper_note = " The paper's counts are against the measured experiment, ours against the " + \
        ("surrogate, so they are not a reproduction of the paper's numbers." if surrogate else "given table.") \
        if paper and df[paper].notna().any() else \
        " The paper's counts are not available in this run (paths.published_model_results not found)."
    return f"{what}, outliers against {ref}: " + "; ".join(parts) + "." + paper_note


def calibration_sentence(b):
    rel = b.out("calibration", "summary")
    if not b.has(rel):
        return f"Calibration residuals: {NOT_BUILT}."
    df = read_csv(b.path(rel))
    res, unit = "rms_residual", "residual_unit"        # lumbar.experiments.calibration's summary columns
    parts = []
    for u, g in df.groupby(unit, sort=False) if unit else [("", df)]:
        names = ", ".join(str(x) for x in g.get("structure", g.index))
        parts.append(f"{fmt(g[res].min())} to {fmt(g[res].max())} {u} ({names})")
    nc = int(df["n_not_converged"].sum()) if "n_not_converged" in df else 0
    kind = " on SURROGATE data" if mentions_surrogate(b.path(rel)) else ""
    return (f"Calibration{kind} in {df['step'].nunique() if 'step' in df else len(df)} steps, RMS residuals: "
            + "; ".join(parts) + f"; {nc} non-converged scenario(s) during the fits.")


def muscle_sentence(b):
    rel = b.out("muscle_model", "metrics")
    if not b.has(rel):
        return f"Muscle model, in-vivo validation: {NOT_BUILT}."
    m = json.loads(b.path(rel).read_text())
    n_tot = m.get("n_total", m.get("n"))
    s = (f"Muscle model (paper 2): predicted vs in-vivo L4-L5 intradiscal pressure over {fmt(m.get('n'))} "
         f"converged of {fmt(n_tot)} activities, ")
    if m.get("r2") is None or m.get("rmse_mpa") is None:
        s += "R2 and RMSE not computed (too few converged activities)"
    else:
        s += f"R2 = {fmt(m.get('r2'), 3)}, RMSE = {fmt(m.get('rmse_mpa'), 3)} MPa"
    pub = b.published.get("idp_validation_r2")
    if pub is not None:
        s += f" (paper: R2 = {fmt(pub['value'])}, {pub['source']})"
    if m.get("r2_all") is not None and m.get("n", n_tot) != n_tot:
        s += (f"; with the IDP of the {fmt(n_tot - m.get('n'))} posture(s) flagged as not converged included, "
              f"R2 = {fmt(m['r2_all'], 3)}, RMSE = {fmt(m['rmse_all_mpa'], 3)} MPa (the muscle capacity table "
              "says where the muscles fall short)")
    if mentions_surrogate(b.path(rel)):
        s += " [SURROGATE data involved]"
    return s + "."


def discrepancy_sentence(b):
    out = []
    rel = b.out("discovery", "default.discovery")
    if b.has(rel):
        d = json.loads(b.path(rel).read_text())
        sur = " (against SURROGATE reference data)" if b.sr_surrogate else ""
        if d.get("named_effect"):
            out.append(f"Discrepancy workflow{sur}: the missing effect that best explains the model-experiment "
                       f"gap is '{fmt(d.get('named_effect'))}' (estimate {fmt(d.get('parameter_estimate'))}, "
                       f"confidence {fmt(d.get('confidence'))}); gap {fmt(d.get('gap_before'))} before, "
                       f"{fmt(d.get('gap_after'))} after adding it.")
        else:
            out.append(f"Discrepancy workflow{sur}: no missing effect is named (gap {fmt(d.get('gap_before'))}; "
                       f"{fmt(d.get('decision')) or 'no candidate passed the naming rule'}).")
    rel = b.out("discovery", "benchmark_summary")
    if b.has(rel):
        d = json.loads(b.path(rel).read_text())
        scal = [(k, v) for k, v in flatten(d) if isinstance(v, (int, float, bool))][:8]
        out.append("Discrepancy benchmark on SURROGATE data with planted effects: "
                   + ", ".join(f"{k} = {fmt(v)}" for k, v in scal) + ".")
    return " ".join(out) if out else f"Discrepancy workflow: {NOT_BUILT}."


def methods(b):
    c = b.cfg
    g = c("geometry", default={}) or {}
    kind = g.get("kind")
    geo = f"Geometry: '{fmt(kind)}'" + {
        "visible_human": f" read from {g.get('path')}",
        "myo_sim": " (myo-sim meshes with project landmarks)",
        "meshes": f" (a user's specimen: vertebra surfaces from {g.get('path')}, {g.get('units')}, {g.get('axes')} "
                  "axes; frame from the anatomy, landmarks placed from the Visible Human atlas)",
        "label_volume": f" (a user's specimen: a CT label volume from {g.get('path')}, meshed by the workflow; frame "
                        "from the anatomy, landmarks placed from the Visible Human atlas)",
    }.get(kind, "")
    b.doc.add(Para(
        f"{geo}; motion segment {fmt(c('fsu', 'level'))}. Characteristic sets: "
        f"{', '.join(SET_LABELS.get(s, s) for s in c('characteristics', 'sets', default=[]))} "
        f"(tables in {fmt(c('characteristics', 'data_dir'))}). Pure moments "
        f"{fmt(c('fsu', 'moments_nm'))} N*m in {fmt(c('fsu', 'directions'))}; facet contact stiffness "
        f"{fmt(c('fsu', 'facet_stiffness_n_per_m'))} N/m; disc shear stiffness "
        + (f"{fmt(c('fsu', 'disc_shear_stiffness_n_per_m'))} N/m." if c('fsu', 'disc_shear_stiffness_n_per_m')
           else "the characteristic set's default.")))
    b.doc.add(Para(which_set_text(b)))
    b.doc.add(Para(
        f"Solver: batched Newton with exact tangent stiffness, tolerances {fmt(c('solver', 'tol_force_n'))} N "
        f"and {fmt(c('solver', 'tol_moment_nm'))} N*m, at most {fmt(c('solver', 'max_iter'))} iterations, "
        f"{fmt(c('solver', 'load_steps'))} load step(s); scenarios without equilibrium are flagged and counted "
        f"as outliers. Random seed {fmt(c('seed'))}."))
    sr = c("stepwise_reduction", default={}) or {}
    if sr:
        ref = reference_text(sr, f"noise SD {fmt(sr.get('noise_sd_deg'))} deg, seed {fmt(c('seed'))}")
        b.doc.add(Para(
            f"Stepwise reduction (paper 1, Sect. 2.1-2.2): calibration in reverse removal order and forward "
            f"simulation at {fmt(sr.get('moments_nm'))} N*m, against {ref}; disc-only rows "
            + (f"derived from the published Eq. 3 fit ({sr.get('disc_only_derived')}); "
               if sr.get("disc_only_derived") else "from the reference table; ") +
            f"rows without a range use mean +- {fmt(sr.get('outlier_tolerance_deg'))} deg."))
    l2 = c("l2s1", default={}) or {}
    if l2:
        ref = reference_text(l2, f"noise SD {fmt(l2.get('noise_sd_mpa'))} MPa")
        b.doc.add(Para(
            f"L2-S1 intradiscal pressure (paper 1, Sect. 2.3): sets {fmt(l2.get('sets'))}, moments "
            f"+-{fmt(l2.get('moment_nm'))} N*m on L2, wire cables from {fmt(l2.get('cables'))}, IDP formula "
            f"'{fmt(l2.get('idp_formula'))}', compared with {ref}."))
    known = {"geometry", "characteristics", "fsu", "solver", "render", "stepwise_reduction", "l2s1", "paths",
             "seed", "run"}      # run.name: where the files are (the appendix lists it), not a method
    for key in b.config:
        if key in known or not isinstance(b.config[key], Mapping):
            continue
        items = flatten(b.config[key])
        b.doc.add(Para(f"{key}: " + "; ".join(f"{k} = {fmt(v)}" for k, v in items) + "."))


def which_set_text(b):
    """Which characteristic set each model uses: "calibrated" is the workflow's own fit, named once."""
    c = b.cfg
    cal = fmt(c("characteristics", "calibrated_dir", default=b.out_dir("calibration", "characteristics").rstrip("/")))
    out = [f"'Calibrated' means this workflow's own calibration (rule calibrate, tables in {cal}, fitted on the "
           f"'{fmt(c('geometry', 'kind'))}' geometry); it is used by the functional unit, the L2-S1 model "
           f"(l2s1.calibrated_characteristics = {fmt(c('l2s1', 'calibrated_characteristics'))}), the other "
           f"levels and the discrepancy discovery (discovery.characteristic_set = "
           f"{fmt(c('discovery', 'characteristic_set'))})."]
    ps = c("muscle_model", "passive_set")
    if ps:
        what = {"workflow_calibrated": f"the workflow's calibrated set ({cal}) applied unchanged at every myo-sim "
                "level (ligament laws on elongation, its facet and disc shear stiffness)",
                "published_table3": f"paper 1's published Table 3 set as printed "
                f"({fmt(c('characteristics', 'data_dir'))}), not the workflow's calibration"}
        out.append(f"The muscle-driven model's passive spine (muscle_model.passive_set = {fmt(ps)}): "
                   f"{what.get(ps, 'the literature set ' + SET_LABELS.get(ps, ps))}.")
    return " ".join(out)



for _anchor, _title, _function, _numbered in (
        ("validation", "Validation on real data", scoreboard_section, False),
        ("flags", "Flags: what needs attention", flags_section, False),
        ("summary", "Summary", summary, False),
        ("methods", "Methods (generated from the configuration)", methods, True)):
    report_section(_anchor, _title, numbered=_numbered)(_function)
