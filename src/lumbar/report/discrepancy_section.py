"""Report section "Where model and experiment disagree": every discovery run of the configuration (the default
stepwise-reduction case, the in-vivo IDP, the vertebral-arch artefact, the intact ROM), the summary on real
measurements and the benchmark on planted effects. Files found by their roles in the discovery's stage manifest
(``b.out("discovery", "<case>.discovery")``); registered after the muscle section."""
from __future__ import annotations

import json
import re
from typing import Mapping

from lumbar.inputs import manifests

from .real_loop import TABLE_COLUMNS, cell
from .document import Bullets, Heading, Para
from .sections import NOT_BUILT, flatten, norm_path, read_csv, fmt, report_section

#: how the report names each discovery run (lumbar.inputs.manifests.DISCOVERY_CASES, in the report's order)
CASE_LABELS = {"default": "stepwise reduction (default case)", "in_vivo": "in-vivo intradiscal pressure",
               "va_artefact": "vertebral-arch removal artefact",
               "intact_rom": "intact L4-L5 range of motion (Yamamoto et al. 1989)"}


def discrepancy_section(b):
    folder = b.out_dir("discovery", "benchmark_table")
    any_d = any(p.startswith(folder) for p in b.inputs) or b.has(b.out("discovery", "benchmark_figure"))
    if not any_d:
        b.doc.add(Para(f"Discrepancy workflow: {NOT_BUILT}.", "note"))
        return
    real_data_section(b)
    for case in manifests.DISCOVERY_CASES:
        label = CASE_LABELS[case]
        found, section = b.out("discovery", f"{case}.discovery"), b.out("discovery", f"{case}.section")
        sur = b.sr_surrogate if case == "default" else b.file_surrogate(found)
        b.doc.add(Heading(f"Case: {label}" + (" [SURROGATE reference data]" if sur else ""), 2))
        if not b.has(found):
            b.doc.add(Para(f"Discovery for case '{case}': {NOT_BUILT}.", "note"))
            continue
        d = json.loads(b.path(found).read_text())
        b.shown.add(norm_path(found))
        keys = ("experiment", "n_scenarios", "named_effect", "parameter_estimate", "gap_before", "gap_after",
                "gap_reduction", "p_value", "null_distribution_size", "confidence", "gap_after_above_threshold",
                "decision", "measured")
        rows = [[k, fmt(d[k])] for k in keys if k in d]
        b.table_block(f"Discovery, case '{case}'", ["quantity", "value"], rows,
                      source=found, surrogate=sur)
        if b.has(section):
            b.shown.add(norm_path(section))
            markdown(b, b.path(section).read_text(), f"case '{case}'", sur,
                     section)
        else:
            ranking = d.get("ranking")
            if isinstance(ranking, list) and ranking:
                if isinstance(ranking[0], Mapping):
                    keys = list(dict.fromkeys(k for r in ranking for k in r))
                    rows = [[fmt(r.get(k)) for k in keys] for r in ranking[:20]]
                else:
                    keys = ["rank", "effect", "criterion"]
                    rows = [[str(i)] + [fmt(x) for x in (r if isinstance(r, (list, tuple)) else [r])]
                            for i, r in enumerate(ranking[:20], 1)]
                b.table_block(f"Ranking of candidate effects, case '{case}'", keys, rows,
                              source=found, surrogate=sur)
        for name, cap in (("disagreement_map", "Where the model disagrees with the experiment"),
                          ("ranking", "Candidate effects ranked by how much of the gap they explain"),
                          ("before_after", "Model vs experiment before and after adding the named effect")):
            if b.has(b.out("discovery", f"{case}.{name}")):
                b.figure(b.out("discovery", f"{case}.{name}"), f"{cap} (case '{case}').", sur)
    b.doc.add(Heading("Benchmark: planted effects on SURROGATE data", 2))
    b.figure(b.out("discovery", "benchmark_figure"), "Discrepancy benchmark: recovery of planted effects "
             "(SURROGATE data).", True)
    summary = b.out("discovery", "benchmark_summary")
    if b.has(summary):
        d = json.loads(b.path(summary).read_text())
        b.table_block("Discrepancy benchmark summary", ["quantity", "value"],
                      [[k, fmt(v)] for k, v in flatten(d)], source=summary,
                      surrogate=True)
    else:
        b.missing("Benchmark summary (benchmark_summary.json)")
    b.csv_table(b.out("discovery", "benchmark_table"), "Discrepancy benchmark cases", surrogate=True)


def real_data_section(b):
    """"What the model is missing, on real data": generated from the discovery's real-data summary table."""
    rel = b.out("discovery", "real_data_summary")
    b.doc.add(Heading("What the model is missing, on real data", 2))
    if not b.has(rel):
        b.missing("Discovery on real measurements (real_data_summary.csv)")
        return
    t = read_csv(b.path(rel))
    t = t.astype(object).where(t.notna(), "")            # empty cells as "" (fillna("") on float columns warns)
    named = t[t["named_effect"].astype(str) != ""]
    few = t[t["note"].astype(str).str.contains("too few rows") | t["decision"].astype(str).str.contains("too few rows")]
    target = t[t["role"].astype(str).str.startswith("calibration target")] if "role" in t.columns else t.iloc[:0]
    text = (f"The discrepancy discovery ran on {len(t)} published dataset(s) the model is compared with. ")
    if len(named):
        text += "Named: " + "; ".join(
            f"{r.dataset}: {r.named_effect} ({r.estimate}, p = {fmt(r.p_value)}; gap {fmt(r.gap_before, 3)} -> "
            f"{fmt(r.gap_after, 3)})" for r in named.itertuples()) + ". "
    else:
        text += "On none of them is a missing effect named at the configured level. "
    if len(few):
        text += ("Too few rows to name anything: " + ", ".join(f"{r.dataset} ({r.n_rows} row(s))"
                                                               for r in few.itertuples()) + ". ")
    rest = t[(t["named_effect"].astype(str) == "") & ~t.index.isin(few.index) & ~t.index.isin(target.index)]
    dec = rest["decision"].astype(str)
    for label, sel in (("Tested, nothing named (consistent with the model and specimen variation, or a nuisance "
                        "explains it)", ~dec.str.startswith("unexplained")),
                       ("Tested, unexplained (the data differ from the model and neither a library effect nor a "
                        "nuisance explains it: something the library does not hold is missing)",
                        dec.str.startswith("unexplained"))):
        if sel.any():
            text += (label + ": " + ", ".join(f"{r.dataset} (gap {fmt(r.gap_before, 3)})"
                                              for r in rest[sel].itertuples()) + ". ")
    if len(target):
        text += ("Not posed, being calibration targets (the fit was made to them): "
                 + ", ".join(str(r.dataset) for r in target.itertuples()) + ". ")
    if "adopted" in t.columns:
        n_adopted = int(t["adopted"].astype(str).str.lower().isin(["true", "1"]).sum())
        text += (f"{n_adopted} effect(s) adopted into the model (config adopted_effects). " if n_adopted else
                 "Nothing is adopted: an effect is adopted only when named on some real rows and judged on others "
                 "it moves, none of which gets worse. ")
    text = text.rstrip()
    b.doc.add(Para(text))
    if all(c in t.columns for c, _ in TABLE_COLUMNS):
        b.table_block("Discovery on real measurements: each real miss, its decision and what would decide it",
                      [h for _, h in TABLE_COLUMNS],
                      [[cell(r[c]) if r[c] != "" else "" for c, _ in TABLE_COLUMNS] for _, r in t.iterrows()],
                      source=rel, note="Decisions at the assumed spread of each dataset and at half and double it "
                                       "(the spreads: the CSV's spread column).")
    else:
        b.csv_table(rel, "Discovery on real measurements", surrogate=False)


def markdown(b, text: str, where: str, surrogate: bool, source: str):
    """A small Markdown text (headings, bullets, pipe tables, paragraphs) as report blocks; image
    references are left out (the figures are shown by themselves)."""
    def clean(s):
        return re.sub(r"[*`]", "", s).strip()
    lines = text.splitlines()
    i, para, bullets = 0, [], []

    def flush():
        if para:
            b.doc.add(Para(clean(" ".join(para))))
            para.clear()
        if bullets:
            b.doc.add(Bullets([clean(b) for b in bullets]))
            bullets.clear()
    while i < len(lines):
        s = lines[i].strip()
        if not s or s.startswith("!["):
            flush()
        elif s.startswith("#"):
            flush()
            b.doc.add(Heading(clean(s.lstrip("#")), 3))
        elif s.startswith(("- ", "* ")):
            if para:
                flush()
            bullets.append(s[2:])
        elif s.startswith("|"):
            flush()
            rows = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                cells = [clean(c) for c in lines[i].strip().strip("|").split("|")]
                if not all(re.fullmatch(r":?-{2,}:?", c) for c in cells if c):
                    rows.append(cells)
                i += 1
            if rows:
                b.table_block(f"Discrepancy table, {where}", rows[0], rows[1:], source=source,
                              surrogate=surrogate)
            continue
        else:
            if bullets:
                flush()
            para.append(s)
        i += 1
    flush()



report_section("discrepancy", "Where model and experiment disagree (discrepancy workflow)",
               after="muscles")(discrepancy_section)
