"""Report sections after the results: "Further figures" (every figure among the inputs not shown above), "Data
provenance" (the kinds and sources of every data table, what is measured and what is surrogate) and the appendix
(the configuration and the report's input files with their SHA-256). Registered at the end, in this order."""
from __future__ import annotations

import hashlib
from pathlib import Path

import pandas as pd

from .document import Para
from .sections import NOT_BUILT, flatten, mentions_surrogate, norm_path, read_csv, fmt, report_section


def other_figures(b):
    rest = sorted(p for p in b.inputs if p.endswith(".png") and p not in b.shown and b.has(p))
    if not rest:
        b.doc.add(Para("Every figure of this configuration is shown above.", "small"))
    else:
        for p in rest:
            b.figure(p, f"{Path(p).stem.replace('_', ' ')}.", mentions_surrogate(p))


def provenance_section(b):
    b.doc.add(Para(
        "Kinds: original_text / original_figure = printed in (or read off a figure of) one of the two papers; "
        "third_party = another publication (cited in source); derived_from_published_fit = computed from "
        "published values; surrogate = a labelled stand-in where nothing is published, never a result."))
    sr = b.cfg("stepwise_reduction", default={}) or {}
    l2 = b.cfg("l2s1", default={}) or {}
    rows = []
    for role, measured, surrogate, derived in (
            ("stepwise reduction ROM reference (Tables 1, 3, 4; Figs. 4-6)", sr.get("measured_table"),
             b.out("virtual_experiment", "table"), sr.get("disc_only_derived")),
            ("L2-S1 IDP reference (Table 5, Fig. 7)", l2.get("measured_table"),
             b.out("virtual_experiment", "idp"), None)):
        if measured:
            rows.append([role, str(measured), "measured (user-supplied table)", kinds_of(b, measured)])
        else:
            rows.append([role, surrogate, "surrogate", kinds_of(b, surrogate)])
        if derived:
            rows.append([role + ", disc-only stage", str(derived), "derived_from_published_fit",
                         kinds_of(b, derived)])
    b.table_block("Experiment tables: measured, derived from a published fit, or surrogate",
                  ["role", "table", "class", "kinds in the file"], rows)
    drows = []
    for rel in sorted(p for p in b.inputs if p.startswith("data/") and p.endswith(".csv")):
        if not b.has(rel):
            continue
        try:
            df = read_csv(b.path(rel))
        except (ValueError, pd.errors.ParserError) as e:
            drows.append([rel, "?", f"(not readable as CSV: {' '.join(str(e).split())[:80]})", ""])
            continue
        kinds = [c for c in df.columns if c == "kind" or c.endswith("_kind")]
        srcs = [c for c in df.columns if c == "source" or c.endswith("_source")]
        kind_txt = "; ".join(
            ", ".join(f"{k}: {n}" for k, n in df[c].fillna("(empty)").value_counts(sort=False).items())
            for c in kinds) or "(no kind column)"
        uniq = list(dict.fromkeys(str(v) for c in srcs for v in df[c].dropna()))
        src_txt = "; ".join(u if len(u) <= 110 else u[:107] + "..." for u in uniq[:3])
        if len(uniq) > 3:
            src_txt += f" (+{len(uniq) - 3} more)"
        drows.append([rel, str(len(df)), kind_txt, src_txt])
    if drows:
        b.table_block("Hand-curated inputs (data/): rows per kind and their sources",
                      ["file", "rows", "kind", "source"], drows)
    else:
        b.doc.add(Para(f"Data tables: {NOT_BUILT} (no data/*.csv among the inputs).", "note"))
    pub = b.cfg("paths", "published_model_results")
    b.doc.add(Para(f"Published model results (the paper's counts beside ours) are read at run time from "
                   f"{pub} (not redistributed): "
                   + ("present." if b.published else "not present in this run, paper columns empty.")))


def kinds_of(b, rel) -> str:
    p = b.inputs.get(norm_path(rel)) or Path(rel)
    if not Path(p).is_file():
        return "(file not present)"
    df = read_csv(p)
    c = "kind" if "kind" in df else "data_kind" if "data_kind" in df else None
    return ", ".join(f"{k}: {n}" for k, n in df[c].value_counts(sort=False).items()) if c else "(no kind column)"


def config_appendix(b):
    b.table_block("Configuration used (every key)", ["key", "value"],
                  [[k, fmt(v, 8)] for k, v in flatten(b.config)])
    rows = []
    for rel in sorted(b.inputs):
        p = b.inputs[rel]
        if p.is_file():
            rows.append([rel, str(p.stat().st_size), hashlib.sha256(p.read_bytes()).hexdigest()[:16]])
        elif p.is_dir():
            rows.append([rel, "(directory)", ""])
        else:
            rows.append([rel, f"({NOT_BUILT})", ""])
    b.table_block("Input files of this report (SHA-256, first 16 hex digits)", ["file", "bytes", "sha256"],
                  rows)



for _anchor, _title, _function in (
        ("figures", "Further figures", other_figures),
        ("provenance", "Data provenance", provenance_section),
        ("appendix", "Appendix: configuration and input files", config_appendix)):
    report_section(_anchor, _title, numbered=False)(_function)
