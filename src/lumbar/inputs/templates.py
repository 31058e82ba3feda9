"""The placeholder grammar of the documentation templates (``docs/templates/*.md``): ``{{ file | selector }}``
reads one value from a result file (rendered by :mod:`lumbar.report.docs`). Kept free of the report's imports so
that the workflow can list a template's input files while it parses (``common.smk``) without loading the report.
"""
from __future__ import annotations

import re

PLACEHOLDER = re.compile(r"\{\{\s*(.+?)\s*\}\}")


def template_files(text: str) -> list[str]:
    """The result files the placeholders of a template read, in order of first use."""
    return list(dict.fromkeys(m.group(1).split("|")[0].strip() for m in PLACEHOLDER.finditer(text)))
