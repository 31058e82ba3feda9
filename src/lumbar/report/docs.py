"""Documents whose numbers are read from result files (showyourwork's rule: no number in prose is typed).

A template is Markdown with placeholders ``{{ path | filter | ... | value }}``; rule ``docs_numbers``
(workflow/rules/report.smk) renders every ``docs/templates/*.md`` into the run's ``report/<name>.md`` (role
report.doc) after the run, so the rendered text always matches the results it sits beside. A placeholder:

* ``path``: a result file, relative to the working directory (a ``.csv`` or ``.tsv`` table, e.g. a job's
  Snakemake benchmark file, or a ``.json`` file); a path under the default results root is read from the run's
  own root (``results_root``: config ``run.name``, :func:`lumbar.inputs.manifests.reroot`);
* ``key=value; key=value`` (CSV, zero or more segments): keep the rows whose columns equal these values (text
  comparison; ``True``/``False`` match boolean columns);
* the last segment, the value: a column name (the one row left; several rows: their values joined by ", "),
  ``count`` (rows left), ``min:col``, ``max:col``, ``sum:col``, ``mean:col``, ``list:col`` (distinct values,
  joined by ", "), ``range:col`` ("min to max"); for JSON, a dotted key (``r2``, ``a.b``).

Numbers print with 3 significant digits (:func:`lumbar.report.sections.fmt`). A placeholder whose rows or key do
not exist in this run renders as ``(not in this run)``: the text says so instead of failing (a small
configuration has fewer rows). :func:`template_files` lists the files a template reads (the rule's inputs).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from ..inputs import manifests
from ..inputs.templates import PLACEHOLDER, template_files  # noqa: F401 - template_files: part of this API
from .sections import fmt

MISSING = "(not in this run)"


def _match(series: pd.Series, value: str) -> pd.Series:
    if value in ("True", "False") and series.dtype == bool:
        return series == (value == "True")
    as_text = series.astype(str)
    ok = as_text == value
    if not ok.any():
        try:
            ok = pd.to_numeric(series, errors="coerce") == float(value)
        except ValueError:
            pass
    return ok


def _csv_value(df: pd.DataFrame, segments: list[str]) -> str:
    *filters, what = segments
    for f in filters:
        for cond in (c for c in f.split(";") if c.strip()):
            if "=" not in cond:
                raise ValueError(f"filter {cond!r}: expected column=value")
            col, val = (x.strip() for x in cond.split("=", 1))
            if col not in df.columns:
                raise KeyError(col)
            df = df[_match(df[col], val)]
    if what == "count":
        return str(len(df))
    if ":" in what:
        agg, col = (x.strip() for x in what.split(":", 1))
        if col not in df.columns:
            raise KeyError(col)
        if not len(df):
            return MISSING
        s = df[col]
        if agg == "list":
            return ", ".join(fmt(v) for v in dict.fromkeys(s.dropna()))
        num = pd.to_numeric(s, errors="coerce")
        if agg == "range":
            return f"{fmt(float(num.min()))} to {fmt(float(num.max()))}"
        return fmt(float(getattr(num, {"min": "min", "max": "max", "sum": "sum", "mean": "mean"}[agg])()))
    if what not in df.columns:
        raise KeyError(what)
    if not len(df):
        return MISSING
    vals = [v.item() if isinstance(v, np.generic) else v for v in df[what]]
    return ", ".join(fmt(v) for v in vals)


def _json_value(obj, key: str) -> str:
    for k in key.split("."):
        if not isinstance(obj, dict) or k not in obj:
            return MISSING
        obj = obj[k]
    return fmt(obj)


def render_placeholder(expr: str, root: Path = Path("."), results_root: str = manifests.RESULTS_DIR) -> str:
    segments = [s.strip() for s in expr.split("|")]
    if len(segments) < 2:
        raise ValueError(f"placeholder {{{{ {expr} }}}}: expected 'path | ... | value'")
    path = root / manifests.reroot(segments[0], results_root)
    if path.suffix == ".json":
        return _json_value(json.loads(path.read_text()), segments[-1])
    try:
        return _csv_value(pd.read_csv(path, sep="\t" if path.suffix == ".tsv" else ","), segments[1:])
    except KeyError as e:
        raise KeyError(f"placeholder {{{{ {expr} }}}}: no column {e} in {segments[0]}") from None


def render(text: str, root=".", results_root: str = manifests.RESULTS_DIR) -> str:
    """A template with every placeholder replaced by its value read from the files under ``root`` (result files
    from the run's ``results_root``). A missing file or column is an error naming the placeholder; rows that do
    not exist render as ``(not in this run)``."""
    root = Path(root)
    return PLACEHOLDER.sub(lambda m: render_placeholder(m.group(1), root, results_root), text)


def render_file(template, output, root=".", results_root: str = manifests.RESULTS_DIR) -> Path:
    from lumbar.inputs.io import write_text_atomic  # noqa: PLC0415
    text = Path(template).read_text()
    head = (f"<!-- rendered from {Path(template).as_posix()} by rule docs_numbers (lumbar.report.docs); "
            "do not edit: edit the template -->\n")
    return write_text_atomic(head + render(text, root, results_root), output)
