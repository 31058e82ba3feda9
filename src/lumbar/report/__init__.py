"""Paper-style report of the workflow's results: one self-contained HTML file and a PDF.

Every number in the report is read from a result or data file; nothing is typed in. Methods are generated
from the configuration. A section, figure or table whose file is not among the given inputs (for example the
muscle study or the discrepancy workflow in a small configuration) is replaced by a one-line
"not built in this configuration" note instead of failing. Results computed against surrogate reference data
say "surrogate" in their caption and table title.

Usage (the workflow's rule ``paper_report`` calls it with the rule's inputs)::

    from lumbar.report import build_report
    build_report(inputs, config, "results/report/paper.html", "results/report/paper.pdf",
                 captions_dir="workflow/report")

The HTML embeds every figure as base64 (``<img data-source="../figures/x.png" src="data:image/png;base64,...">``;
``data-source`` is the figure file relative to the HTML file) and every table carries ``data-source`` with the
CSV it was drawn from. The PDF is drawn with reportlab (pure Python) with ``invariant=1``: no time stamp, a fixed
document id, so the same inputs give the same bytes.

Modules: :mod:`.document` (the document model), :mod:`.sections` (:class:`~.sections.ReportBuilder`: the sections,
read from the result files and the configuration), :mod:`.html_renderer`, :mod:`.pdf_renderer`; this module holds
the entry points.
"""
from __future__ import annotations

from typing import Iterable, Mapping

from lumbar.inputs.io import atomic_writer, write_text_atomic

from .document import Doc, Para
from .html_renderer import render_html
from .pdf_renderer import render_pdf
from .sections import NOT_BUILT, SECTIONS, ReportBuilder, fmt, report_section
from . import load_sharing_section as _load_sharing_section  # noqa: F401, E402 - registers its report section
from . import posterior as _posterior_section  # noqa: F401, E402 - registers its report section
from . import landmark_accuracy_section as _landmark_accuracy_section  # noqa: F401, E402 - registers its section

__all__ = ["build_document", "build_report", "render_html", "render_pdf", "NOT_BUILT", "ReportBuilder", "Doc", "fmt",
           "SECTIONS", "report_section"]


def build_document(inputs: Iterable, config: Mapping, html_path, captions_dir=None, published=None, logs_dir=None):
    """The report as a document model (``Doc``) and its builder, without writing anything."""
    b = ReportBuilder(inputs, config, html_path, captions_dir=captions_dir, published=published, logs_dir=logs_dir)
    return b.build(), b


def build_report(inputs: Iterable, config: Mapping, html_path, pdf_path, captions_dir=None,
                 published=None, logs_dir=None) -> dict:
    """Write the paper-style report as HTML (self-contained) and PDF.

    ``inputs``: paths (relative to the working directory, or absolute) of every result and data file the report
    may show; a file that is not among them is reported as "not built in this configuration".
    ``config``: the validated workflow configuration (methods, labels). ``captions_dir``: directory of the
    ``<output stem>.rst`` captions (workflow/report). ``published``: the published-results CSV (paper values,
    optional). ``logs_dir``: the workflow's logs (``logs/``); their WARNING lines make the "Flags" section.
    Returns a summary: figure and table counts, which inputs were not built and the warnings listed.
    """
    inputs = list(inputs)
    doc, b = build_document(inputs, config, html_path, captions_dir, published, logs_dir)
    write_text_atomic(render_html(doc, b), html_path)
    pdf = render_pdf(doc, b)
    with atomic_writer(pdf_path, "wb") as f:
        f.write(pdf)
    notes = [x.text for x in doc.blocks if isinstance(x, Para) and x.style == "note"]
    return {"figures": b.n_fig, "tables": b.n_tab, "not_built": notes, "warnings": b.warnings() or [],
            "surrogate": {"stepwise_reduction": b.sr_surrogate, "idp": b.idp_surrogate}}
