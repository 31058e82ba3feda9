"""Paper-style report of the workflow's results: one self-contained HTML file and a PDF.

Every number in the report is read from a result or data file; nothing is typed in. Methods are generated
from the configuration. A section, figure or table whose file is not among the given inputs (for example the
muscle study or the discrepancy workflow in a small configuration) is replaced by a one-line
"not built in this configuration" note instead of failing. Results computed against surrogate reference data
say "surrogate" in their caption and table title.

Usage (the workflow's rule ``paper_report`` calls it with the rule's inputs)::

    from lumbar.report import build_report
    build_report(inputs, config, html_path, pdf_path, captions_dir="workflow/report")

The HTML embeds every figure as base64 (``<img data-source="../figures/x.png" src="data:image/png;base64,...">``;
``data-source`` is the figure file relative to the HTML file) and every table carries ``data-source`` with the
CSV it was drawn from. The PDF is drawn with reportlab (pure Python) with ``invariant=1``: no time stamp, a fixed
document id, so the same inputs give the same bytes.

Modules: :mod:`.document` (the document model), :mod:`.sections` (:class:`~.sections.ReportBuilder` and the
registry of sections), the sections (:mod:`.front_sections`, :mod:`.paper_sections`, :mod:`.load_sharing_section`,
:mod:`.posterior`, :mod:`.discrepancy_section`, :mod:`.appendix_sections`; each finds its files by their roles in
the stage manifests, :mod:`lumbar.inputs.manifests`, under the run's results root), :mod:`.html_renderer`,
:mod:`.pdf_renderer`; this module holds the entry points.
"""
from __future__ import annotations

import importlib
from typing import Iterable, Mapping

from lumbar.inputs import manifests

from lumbar.inputs.io import atomic_writer, write_text_atomic

from .document import Doc, Para
from .html_renderer import render_html
from .pdf_renderer import render_pdf
from .sections import NOT_BUILT, SECTIONS, ReportBuilder, fmt, report_section
# the modules of the sections register them on import, in this order (a section placed after= another goes there)
from . import front_sections as _front_sections  # noqa: F401, E402
from . import paper_sections as _paper_sections  # noqa: F401, E402
from . import discrepancy_section as _discrepancy_section  # noqa: F401, E402
from . import appendix_sections as _appendix_sections  # noqa: F401, E402

# a stage's own section: the module its stage manifest names (lumbar.inputs.manifests, report_module), imported in
# manifest order; it registers itself (report_section, placed with after=)
for _module in manifests.report_modules():
    importlib.import_module(_module)

__all__ = ["build_document", "build_report", "render_html", "render_pdf", "NOT_BUILT", "ReportBuilder", "Doc", "fmt",
           "SECTIONS", "report_section"]


def build_document(inputs: Iterable, config: Mapping, html_path, captions_dir=None, published=None, logs_dir=None,
                   logs_exclude=()):
    """The report as a document model (``Doc``) and its builder, without writing anything."""
    b = ReportBuilder(inputs, config, html_path, captions_dir=captions_dir, published=published, logs_dir=logs_dir,
                      logs_exclude=logs_exclude)
    return b.build(), b


def build_report(inputs: Iterable, config: Mapping, html_path, pdf_path, captions_dir=None,
                 published=None, logs_dir=None, logs_exclude=()) -> dict:
    """Write the paper-style report as HTML (self-contained) and PDF.

    ``inputs``: paths (relative to the working directory, or absolute) of every result and data file the report
    may show; a file that is not among them is reported as "not built in this configuration".
    ``config``: the validated workflow configuration (methods, labels). ``captions_dir``: directory of the
    ``<output stem>.rst`` captions (workflow/report). ``published``: the published-results CSV (paper values,
    optional). ``logs_dir``: the workflow's logs (``logs/``, a named run's ``logs/<name>/``); their WARNING lines
    make the "Flags" section, except those in the sub-folders ``logs_exclude`` (other runs' logs).
    Returns a summary: figure and table counts, which inputs were not built and the warnings listed.
    """
    inputs = list(inputs)
    doc, b = build_document(inputs, config, html_path, captions_dir, published, logs_dir, logs_exclude)
    write_text_atomic(render_html(doc, b), html_path)
    pdf = render_pdf(doc, b)
    with atomic_writer(pdf_path, "wb") as f:
        f.write(pdf)
    notes = [x.text for x in doc.blocks if isinstance(x, Para) and x.style == "note"]
    return {"figures": b.n_fig, "tables": b.n_tab, "not_built": notes, "warnings": b.warnings() or [],
            "surrogate": {"stepwise_reduction": b.sr_surrogate, "idp": b.idp_surrogate}}
