"""Report sections of the results of the two papers: the models (Figs. 1 and 3), the calibration on the stepwise
reduction (Tables 1-3, Figs. 4-5), its forward simulation (Table 4, Fig. 6), the L2-S1 intradiscal pressure (Table 5,
Fig. 7) and the muscle-driven model of paper 2. Every file is found by its role in the stage manifests
(``b.out(stage, role)``); registered after the methods, in this order."""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from .document import CHECK, CROSS, NC, Para
from .front_sections import muscle_sentence
from .sections import (
    VARIANT_NAMES,
    paper2_claims_sentence,
    DIRECTION_ABBR,
    NOT_BUILT,
    SET_LABELS,
    norm_path,
    read_csv,
    fmt,
    human_value,
    report_section,
)


def model_section(b):
    b.figure(b.out("geometry", "figure"), "L4-L5 functional spinal unit (Fig. 1 analog).", label="Fig. 1")
    b.figure(b.out("l2s1", "fig3"), "L2-S1 lumbar spine with wire cables (Fig. 3 analog).",
             label="Fig. 3")
    b.csv_table(b.out("geometry", "table"), "Geometry of the motion segments (disc, facets, ligament fibres)")


def calibration_section(b):
    s = b.sr_surrogate
    b.csv_table(b.out("calibration", "table1"), "Disc torque-angle parameters, Eq. 3 (Table 1 analog)", s,
                label="Table 1")
    b.figure(b.out("calibration", "fig4"), "Disc torque-angle characteristics (Fig. 4 analog).", s,
             label="Fig. 4")
    b.csv_table(b.out("calibration", "table2"), "Facet joint regression surfaces, Eq. 4 (Table 2 analog)",
                label="Table 2")
    b.csv_table(b.out("calibration", "table3"),
                "Ligament force-strain parameters, Eq. 7 (Table 3 analog)",
                s, label="Table 3")
    b.figure(b.out("calibration", "fig5"), "Ligament force-strain characteristics (Fig. 5 analog).",
             s, label="Fig. 5")
    b.csv_table(b.out("calibration", "summary"),
                "Calibration steps and RMS residuals (identifiable: the stage's ROM responds to the structure; "
                "at_bound: a fitted parameter ends within 1 % of its bound)", s)
    targets = b.out("calibration", "targets")
    origin = ""
    if b.has(targets):
        t = read_csv(b.path(targets))
        origin = "; ".join(dict.fromkeys(str(v).split(",")[0] for v in t["source"])) if len(t) else ""
    b.csv_table(b.out("calibration", "real_fit"),
                f"Final fit on the real targets (intact ROM at 10 N*m{', ' + origin if origin else ''}) and "
                "the admissibility criteria: force scales, facet stiffness, disc shear stiffness within its "
                "sourced range", False)


def forward_section(b):
    s = b.sr_surrogate
    b.figure(b.out("stepwise_reduction", "fig6"), "Range of motion per reduction stage (Fig. 6 analog).", s,
             label="Fig. 6")
    b.csv_table(b.out("stepwise_reduction", "vs_paper"),
                "ROM outlier counts per characteristic set beside the paper's", s)
    grid_table4(b, s)
    b.figure(b.out("stepwise_reduction", "grid"), "Table 4 as a figure.", s)


def idp_section(b):
    s = b.idp_surrogate
    internal = b.out("l2s1", "internal")
    b.figure(b.out("l2s1", "fig7"), "L4-L5 intradiscal pressure per muscle set-up and load case (Fig. 7 analog).",
             s, label="Fig. 7")
    b.csv_table(b.out("l2s1", "vs_paper"), "IDP outlier counts per characteristic set beside the paper's", s)
    grid_table5(b, s)
    b.figure(b.out("l2s1", "grid"), "Table 5 as a figure.", s)
    if b.has(internal):
        df = read_csv(b.path(internal))
        num = [c for c in df.columns if c.endswith(("_n", "_nm", "_mpa"))
               and not c.startswith("residual") and pd.api.types.is_numeric_dtype(df[c])]
        agg = df.groupby("set", sort=False)[num].agg(["min", "max"]) if "set" in df and num else None
        if agg is not None:
            rows = [[c] + [f"{fmt(agg.loc[st, (c, 'min')])} to {fmt(agg.loc[st, (c, 'max')])}"
                           if fmt(agg.loc[st, (c, "max")]) else "" for st in agg.index] for c in num]
            b.table_block("Internal loads at L4-L5 over the 49 scenarios (min to max per set)",
                          ["quantity"] + [SET_LABELS.get(st, st) for st in agg.index], rows,
                          source=internal,
                          note=b.caption(internal, ""), surrogate=s)
    else:
        b.missing("Internal loads (l2s1_internal_loads.csv)")


def grid_table4(b, surrogate):
    rel = b.out("stepwise_reduction", "synopsis")
    if not b.has(rel):
        b.missing("Table 4 synopsis (table4_rom_synopsis.csv)")
        return
    df = read_csv(b.path(rel))
    sets = list(dict.fromkeys(df["set"]))
    dirs = [d for d in DIRECTION_ABBR if d in set(df["direction"])] + \
        [d for d in dict.fromkeys(df["direction"]) if d not in DIRECTION_ABBR]
    keyed = {(r.set, r.stage, r.moment_nm, r.direction): r for r in df.itertuples(index=False)}
    rows = []
    for stage in dict.fromkeys(df["stage"]):
        for m in sorted(set(df.loc[df["stage"] == stage, "moment_nm"])):
            row = [human_value(stage), f"{fmt(m)} N\u00b7m"]
            for st in sets:
                for d in dirs:
                    r = keyed.get((st, stage, m, d))
                    row.append("" if r is None else NC if not bool(r.converged) else
                               CROSS if bool(r.outlier) else CHECK)
            rows.append(row)
    header = ["stage", "moment"] + [DIRECTION_ABBR.get(d, d) for _ in sets for d in dirs]
    group = [("", 2)] + [(SET_LABELS.get(s, s), len(dirs)) for s in sets]
    b.table_block("Synopsis of the forward-simulated stepwise reduction (Table 4 analog): "
                  f"{CHECK} within the reference range, {CROSS} outlier, {NC} no equilibrium",
                  header, rows, source=rel, note=b.caption(rel, ""), surrogate=surrogate,
                  group_header=group, marks=True, label="Table 4")


def grid_table5(b, surrogate):
    rel = b.out("l2s1", "synopsis")
    if not b.has(rel):
        b.missing("Table 5 synopsis (table5_idp_synopsis.csv)")
        return
    df = read_csv(b.path(rel))
    sets = list(dict.fromkeys(df["set"]))
    keyed = {(r.set, r.muscle_setup, r.load_case): r for r in df.itertuples(index=False)}
    rows = []
    for mu in dict.fromkeys(df["muscle_setup"]):
        for lc in dict.fromkeys(df.loc[df["muscle_setup"] == mu, "load_case"]):
            row = [human_value(mu), human_value(lc)]
            for st in sets:
                r = keyed.get((st, mu, lc))
                row.append("" if r is None else NC if not bool(r.converged) else
                           CROSS if bool(r.outlier) else CHECK)
            rows.append(row)
    b.table_block("Synopsis of the forward-simulated IDP experiment (Table 5 analog): "
                  f"{CHECK} within mean +- SD, {CROSS} outlier, {NC} no equilibrium",
                  ["muscle set-up", "load case"] + [SET_LABELS.get(s, s) for s in sets], rows, source=rel,
                  note=b.caption(rel, ""), surrogate=surrogate, marks=True, label="Table 5")


#: paper 2's claim quantities and sensitivity parameters in words (the claims table's identifiers)
CLAIM_QUANTITY_WORDS = {
    "idp_r2": "in-vivo IDP, R2 of the linear fit", "idp_mpa": "L4-L5 IDP", "idp_moment_share_pct": "moment's share of IDP",
    "idp_moment_share_max_pct": "largest moment share of IDP over the sweep", "mf_sl_um": "multifidus sarcomere length",
    "extensor_active_n": "extensor active force", "extensor_passive_n": "extensor passive force",
    "abdominal_active_n": "abdominal active force",
    "extensor_active_flexion_over_standing": "extensor active force, flexion / standing",
    "intervertebral_rotation_within_range": "intervertebral rotations within Wong et al.'s range",
    "idp_change_pct": "IDP change", "idp_abs_change_pct": "|IDP change| at most",
    "idp_change_between_pct": "IDP change between", "idp_ratio_between_pct": "IDP change between",
    "reached": "posture reached", "mean_abs_change_flexion_over_standing": "mean |change|, flexion / standing"}
CLAIM_PARAMETER_WORDS = {"ssl_um": "SSL [um]", "k_n_per_cm2": "K [N/cm2]", "in_situ_sl_um": "in-situ SL [um]",
                         "spt_n_per_cm2": "SpT [N/cm2]", "pennation_deg": "pennation [deg]"}
#: reasons that mean "this run did not run it", shown as "not run" (the CSV keeps the reason)
_NOT_RUN = ("scenario not in this run's sweep", "the sensitivity sweep is not run on this variant",
            "activity not in this run", "level not in this run's")


def _claim_words(r) -> str:
    q = CLAIM_QUANTITY_WORDS.get(r["quantity"], human_value(r["quantity"]))
    post = human_value(r["posture"]) if isinstance(r["posture"], str) else ""
    par = r["parameter"] if isinstance(r["parameter"], str) else ""
    if r["claim_class"] == "table1":
        return f"{q} at {r['value']}, {post}"
    bits = [q, post]
    if par:
        bits.append(f"{CLAIM_PARAMETER_WORDS.get(par, par)} {r['value']}")
    if isinstance(r["ssl_um"], str) and r["ssl_um"]:
        bits.append(f"with SSL {r['ssl_um']} um")
    if isinstance(r["scope"], str) and r["scope"]:
        bits.append(r["scope"])
    return ", ".join(x for x in bits if x)


def _claim_cell(r) -> str:
    if r is None:
        return ""
    reason = r["reason"] if isinstance(r["reason"], str) else ""
    if r["verdict"] == "not comparable" and any(reason.startswith(x) for x in _NOT_RUN):
        return "not run"
    v = r["ours"]
    txt = "" if pd.isna(v) else fmt(float(v), 3)
    return f"{txt} ({r['verdict']}{'; ' + reason if reason else ''})".strip()


def paper2_claims_tables(b):
    """The claims the paper leads with (validation, flexion-relaxation, headline sensitivity changes, reachability,
    directions) beside ours, per variant; the counts of every class; whether each passive chain fits the muscle
    model's geometry. Table 1 and the small-effect bounds are counted there and listed in the CSV."""
    rel = b.out("muscle_model", "reproduction")
    if b.has(rel):
        t = read_csv(b.path(rel))
        b.shown.add(norm_path(rel))
        keep = t[t["claim_class"].isin(["validation", "flexion_relaxation", "sensitivity_headline",
                                        "reachability", "sensitivity_direction", "rotations"])]
        variants = sorted(dict.fromkeys(t["variant"]), key=lambda v: (v != "reproduction", v))
        rows = []
        for key, d in keep.groupby("claim_id", sort=False):
            by = {r["variant"]: r for _, r in d.iterrows()}
            cells = [_claim_cell(by.get(v)) for v in variants]
            if all(c in ("not run", "") for c in cells):
                continue
            r = next(iter(by.values()))
            paper = r["paper"]
            try:
                paper = fmt(float(paper), 3)
            except (TypeError, ValueError):
                paper = "" if pd.isna(paper) else str(paper)
            unit = r["unit"] if isinstance(r["unit"], str) and r["unit"] != "-" else ""
            rows.append([human_value(r["claim_class"]), _claim_words(r), f"{paper} {unit}".strip()] + cells)
        b.table_block("Paper 2's stated results beside ours (Table 1 and the small-effect bounds: counts below, every "
                      "row with its quote in the CSV)", ["claim class", "claim", "paper"] +
                      [VARIANT_NAMES.get(v, v) for v in variants], rows, source=rel, note=b.caption(rel, ""))
    b.csv_table(b.out("muscle_model", "reproduction_counts"), "Verdict counts of paper 2's claims per variant and "
                "claim class")
    b.csv_table(b.out("muscle_model", "chain_admissibility"), "Each passive chain on the muscle model's geometry: "
                "facet overlap at rest and whether every level flexes in 36 deg flexion")
    b.csv_table(b.out("muscle_model", "rotations"), "Intervertebral rotations in the rotation-check postures "
                "(change from upright standing)")


def muscle_section(b):
    metrics = b.out("muscle_model", "metrics")
    files = [b.out("muscle_model", role) for role in ("segment_loads", "validation", "metrics", "flexion_relaxation",
                                                       "capacity", "sensitivity", "directions", "sobol")]
    prefix = b.out_dir("muscle_model", "figure") + "muscle_"          # every figure of the muscle study
    figs = sorted(p for p in b.inputs if p.startswith(prefix) and p.endswith(".png"))
    if not any(b.has(f) for f in files) and not figs:
        b.doc.add(Para(f"Muscle study: {NOT_BUILT}.", "note"))
        return
    claims = paper2_claims_sentence(b)
    if claims:
        b.doc.add(Para(claims))
        paper2_claims_tables(b)
    if b.has(metrics):
        b.doc.add(Para(muscle_sentence(b)))
        b.shown.add(norm_path(metrics))
    else:
        b.missing("In-vivo validation metrics (in_vivo_metrics.json)")
    b.figure(b.out("muscle_model", "figure"), "Predicted vs in-vivo L4-L5 intradiscal pressure.")
    b.csv_table(b.out("muscle_model", "validation"), "In-vivo validation: predicted and measured IDP per activity")
    b.csv_table(b.out("muscle_model", "segment_loads"), "Segmental loads of the musculoskeletal model")
    b.csv_table(b.out("muscle_model", "flexion_relaxation"), "Flexion-relaxation: active and passive muscle forces")
    b.csv_table(b.out("muscle_model", "capacity"), "Muscle capacity: sagittal moments about each level and the "
                "largest extension moment of the active fascicles")
    b.csv_table(b.out("muscle_model", "sensitivity"), "Sensitivity of L4-L5 IDP to the muscle parameters")
    b.csv_table(b.out("muscle_model", "directions"), "The paper's sensitivity statements: stated and simulated "
                "direction of the L4-L5 IDP change")
    sobol = b.out("muscle_model", "sobol")
    cols = ["posture", "parameter", "S1", "S1_lo", "S1_hi", "ST", "ST_lo", "ST_hi", "q2_loo", "n_train",
            "stable"]   # the rest: caption and CSV
    try:
        have = list(pd.read_csv(b.path(sobol), nrows=0).columns) if b.has(sobol) else []
    except (ValueError, pd.errors.ParserError):
        have = []
    b.csv_table(sobol, "Sobol indices of L4-L5 IDP (polynomial chaos expansion; S1/ST_lo-hi: bootstrap 95 % "
                "intervals)", columns=cols if set(cols) <= set(have) else None)
    for f in figs:
        if norm_path(f) not in b.shown:
            name = Path(f).stem.replace("muscle_", "").replace("_", " ")
            b.figure(f, f"Muscle study: {name}.")



for _anchor, _title, _function in (
        ("models", "Models", model_section),
        ("calibration", "Calibration on the stepwise reduction (backwards)", calibration_section),
        ("forward", "Forward simulation of the stepwise reduction", forward_section),
        ("idp", "Intradiscal pressure in the L2-S1 spine with wire cables", idp_section),
        ("muscles", "Paraspinal muscles and spinal loading (paper 2)", muscle_section)):
    report_section(_anchor, _title, after="methods" if _anchor == "models" else None)(_function)
