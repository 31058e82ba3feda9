"""Report text of the discovery loop on real data: one paragraph and one table per run from
the real-data summary (role ``discovery.real_data_summary``, rule discovery_real_data_summary); every number is read
from that table, none is typed here. The table's columns (:data:`TABLE_COLUMNS`) are those of the discrepancy section's
"What the model is missing, on real data" (lumbar.report.discrepancy_section.real_data_section)."""
from __future__ import annotations

import math

import pandas as pd

#: the summary's columns the table shows, with their headings
TABLE_COLUMNS = (("dataset", "dataset"), ("role", "role"), ("n_rows", "rows"), ("largest_miss", "largest miss"),
                 ("largest_z", "z"), ("decision", "decision"), ("decision_half_spread", "at half spread"),
                 ("decision_double_spread", "at double spread"), ("why_not_named", "why nothing was named"),
                 ("what_would_decide", "what would decide it"))


def cell(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    if isinstance(v, float):
        return f"{v:.2f}"
    return str(v).replace("|", "/")


def real_misses_markdown(summary: pd.DataFrame) -> str:
    """Markdown: how many real datasets were posed, how many named an effect, how many were adopted, then the table
    (dataset, role, rows, largest miss with its z, decision at the assumed, half and double spread, why nothing was
    named, what would decide it)."""
    need = {c for c, _ in TABLE_COLUMNS} | {"named_effect", "adopted"}
    miss = sorted(need - set(summary.columns))
    if miss:
        raise ValueError(f"real-data summary: column(s) {miss} missing; expected the columns of "
                         f"lumbar.discovery.real_data.SUMMARY_COLUMNS")
    n = len(summary)
    named = summary["named_effect"].fillna("").astype(str).str.len().gt(0)
    adopted = summary["adopted"].astype(str).str.lower().isin(["true", "1"])
    target = summary["role"].fillna("").astype(str).str.startswith("calibration target")
    lines = [f"The calibrated model was compared with {n} real dataset(s); {int(target.sum())} of them a calibration "
             f"target (not posed as a miss). The discovery named an effect on {int(named.sum())} and "
             f"{int(adopted.sum())} effect(s) were adopted. Each posed dataset was decided at its assumed spread and "
             f"again at half and double of it.", "",
             "| " + " | ".join(h for _, h in TABLE_COLUMNS) + " |", "|" + "---|" * len(TABLE_COLUMNS)]
    for row in summary.to_dict("records"):
        lines.append("| " + " | ".join(cell(row.get(c)) for c, _ in TABLE_COLUMNS) + " |")
    return "\n".join(lines) + "\n"
