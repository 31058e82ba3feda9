"""PDF renderer of the report (reportlab, pure Python, ``invariant=1``: no time stamp and a fixed document id,
so the same inputs give the same bytes)."""
from __future__ import annotations

import html
import io
import logging
from pathlib import Path

import matplotlib
from PIL import Image as PILImage
from reportlab import rl_config
from reportlab.lib import colors
from reportlab.lib.fonts import addMapping
from reportlab.lib.pagesizes import A4
from reportlab.lib.styles import ParagraphStyle, getSampleStyleSheet
from reportlab.lib.units import mm
from reportlab.pdfbase import pdfmetrics
from reportlab.pdfbase.ttfonts import TTFont
from reportlab.platypus import Image, KeepTogether, PageBreak, Paragraph, SimpleDocTemplate, Spacer
from reportlab.platypus import Table as RLTable
from reportlab.platypus import TableStyle

from lumbar import __version__

from .document import CHECK, CROSS, LINK, NC, Bullets, Contents, Doc, Figure, Heading, Para, Table
from .sections import ReportBuilder

log = logging.getLogger(__name__)


_FONT = {"regular": "Helvetica", "bold": "Helvetica-Bold", "italic": "Helvetica-Oblique"}


def _register_fonts() -> bool:
    """Use matplotlib's DejaVu Sans (a pinned dependency) in the PDF: it has the check and cross marks and
    every character of the captions; falls back to the standard Helvetica (Latin-1 only)."""
    if _FONT["regular"] == "DejaVuSans":
        return True
    try:
        ttf = Path(matplotlib.get_data_path()) / "fonts" / "ttf"
        faces = {"DejaVuSans": "DejaVuSans.ttf", "DejaVuSans-Bold": "DejaVuSans-Bold.ttf",
                 "DejaVuSans-Oblique": "DejaVuSans-Oblique.ttf", "DejaVuSans-BoldOblique": "DejaVuSans-BoldOblique.ttf"}
        for name, file in faces.items():
            pdfmetrics.registerFont(TTFont(name, str(ttf / file)))
        addMapping("DejaVuSans", 0, 0, "DejaVuSans")
        addMapping("DejaVuSans", 1, 0, "DejaVuSans-Bold")
        addMapping("DejaVuSans", 0, 1, "DejaVuSans-Oblique")
        addMapping("DejaVuSans", 1, 1, "DejaVuSans-BoldOblique")
    except Exception as e:  # noqa: BLE001 - the PDF is still written with the standard fonts
        log.warning("DejaVu Sans not available for the PDF (%s): Helvetica, marks drawn as text", e)
        return False
    _FONT.update(regular="DejaVuSans", bold="DejaVuSans-Bold", italic="DejaVuSans-Oblique")
    return True


def _pdf_text(s: str) -> str:
    s = str(s)
    if _FONT["regular"] == "Helvetica":
        s = s.replace(CHECK, "ok").replace(CROSS, "x")
        s = s.encode("cp1252", "replace").decode("cp1252")
    return html.escape(s, quote=False)


#: cell padding (left and right, each) of every table, pt
PAD = 2.0
#: font sizes a table may use, largest first: the largest at which every word fits its column
CELL_SIZES = (7.0, 6.5, 6.0)


def _styles():
    unicode_font = _register_fonts()
    reg, bold, ital = _FONT["regular"], _FONT["bold"], _FONT["italic"]
    ss = getSampleStyleSheet()
    body = ParagraphStyle("body", parent=ss["BodyText"], fontName=reg)
    st = {
        "title": ParagraphStyle("t", parent=ss["Title"], fontName=bold, fontSize=14, leading=17, spaceAfter=4),
        1: ParagraphStyle("h1", parent=ss["Heading1"], fontName=bold, fontSize=14, keepWithNext=1),
        2: ParagraphStyle("h2", parent=ss["Heading2"], fontName=bold, fontSize=11.5, keepWithNext=1),
        3: ParagraphStyle("h3", parent=ss["Heading3"], fontName=bold, fontSize=10, keepWithNext=1),
        "p": ParagraphStyle("p", parent=body, fontSize=9, leading=11.5),
        "abstract": ParagraphStyle("a", parent=body, fontSize=9, leading=11.5, backColor="#f2f2f2",
                                   borderPadding=3, spaceAfter=6),
        "small": ParagraphStyle("s", parent=body, fontSize=8, leading=10),
        "note": ParagraphStyle("n", parent=body, fontSize=8.5, textColor="#777777", fontName=ital),
        "cap": ParagraphStyle("c", parent=body, fontSize=8, leading=10, keepWithNext=1),
        "toc": ParagraphStyle("toc", parent=body, fontSize=9, leading=11.5, leftIndent=8),
    }
    for size in CELL_SIZES:       # table cells: a word is never split (splitLongWords=0); the layout makes it fit
        st[("cell", size)] = ParagraphStyle(f"cell{size}", parent=body, fontSize=size, leading=size + 1.2,
                                            splitLongWords=0)
        st[("cellb", size)] = ParagraphStyle(f"cellb{size}", parent=body, fontSize=size, leading=size + 1.2,
                                             fontName=bold, splitLongWords=0)
    return st, unicode_font


def _words_width(text: str, font: str, size: float) -> tuple[float, float]:
    """(widest word, whole text on one line) of a cell's text, pt."""
    words = str(text).split() or [""]
    return (max(pdfmetrics.stringWidth(w, font, size) for w in words),
            pdfmetrics.stringWidth(" ".join(words), font, size))


def column_widths(header, rows, width, size, group_header=None, long_text=0.45):
    """Column widths [pt] of a table at font ``size`` in a frame ``width`` wide, or None when it cannot fit.

    Every column is at least as wide as its widest word (a word is never wrapped inside), plus padding; the
    space left is shared in proportion to how much each column needs to hold its longest cell on one line
    (a column's one-line width is capped at ``long_text`` of the frame, so a sentence column wraps, at spaces).
    A spanning group header needs its widest word over the columns it spans."""
    reg, bold = _FONT["regular"], _FONT["bold"]
    ncol = len(header)
    lo, hi = [0.0] * ncol, [0.0] * ncol
    for r, font in [(header, bold)] + [(r, reg) for r in rows]:
        for i, v in enumerate(list(r)[:ncol]):
            w, full = _words_width(_plain(v), font, size)
            lo[i] = max(lo[i], w + 2 * PAD + 0.5)
            hi[i] = max(hi[i], min(full, long_text * width) + 2 * PAD + 0.5)
    if group_header:
        c0 = 0
        for text, n in group_header:
            w, _ = _words_width(text, bold, size)
            have = sum(lo[c0:c0 + n])
            if w + 2 * PAD + 0.5 > have:
                for i in range(c0, c0 + n):
                    lo[i] += (w + 2 * PAD + 0.5 - have) / n
            c0 += n
    hi = [max(h, m) for h, m in zip(hi, lo)]
    if sum(lo) > width + 1e-6:
        return None
    if sum(hi) <= width:
        return hi
    extra = width - sum(lo)
    need = [h - m for h, m in zip(hi, lo)]
    return [m + extra * n / sum(need) for m, n in zip(lo, need)]


def _plain(v) -> str:
    return str(v)


def split_columns(header, rows, width, key_cols, size, group_header=None):
    """A table too wide for the frame as parts of columns, each with the ``key_cols`` leading columns repeated:
    [(column indices, widths), ...], or None when even one data column does not fit beside the key columns."""
    if group_header:
        return None
    ncol = len(header)
    keys = list(range(min(key_cols, ncol - 1)))
    parts, cur = [], []
    for c in range(len(keys), ncol):
        trial = keys + cur + [c]
        w = column_widths([header[i] for i in trial], [[r[i] for i in trial] for r in rows], width, size)
        if w is None:
            if not cur:
                return None
            parts.append(keys + cur)
            cur = [c]
        else:
            cur.append(c)
    if cur:
        parts.append(keys + cur)
    out = []
    for cols in parts:
        w = column_widths([header[i] for i in cols], [[r[i] for i in cols] for r in rows], width, size)
        if w is None:
            return None
        out.append((cols, w))
    return out


def table_flowables(b: Table, st: dict, width: float, marks: dict) -> list:
    """A document table as reportlab flowables: its title, the table (or its column parts, when it is wider than
    the frame at the smallest font) and its note."""
    ncol = max(len(b.header), max((len(r) for r in b.rows), default=0))
    header = list(b.header) + [""] * (ncol - len(b.header))
    rows = [list(r) + [""] * (ncol - len(r)) for r in b.rows]
    plan = None
    for size in CELL_SIZES:
        w = column_widths(header, rows, width, size, b.group_header)
        if w is not None:
            plan = (size, [(list(range(ncol)), w)])
            break
    if plan is None:
        size = CELL_SIZES[-1]
        parts = split_columns(header, rows, width, b.key_cols, size, b.group_header)
        if parts is None:      # no split keeps a word whole: the smallest font, columns by share (words may wrap)
            log.warning("table %r: a word is wider than the page even alone in its column", b.title)
            parts = [(list(range(ncol)), [width / ncol] * ncol)]
        plan = (size, parts)
    size, parts = plan
    out = []
    for k, (cols, colw) in enumerate(parts):
        title = b.title + (f" (part {k + 1} of {len(parts)})" if len(parts) > 1 else "")
        data, spans = [], []
        nhead = 1
        if b.group_header and len(parts) == 1:
            row, c0 = [], 0
            for t, n in b.group_header:
                row += [Paragraph(_pdf_text(t), st[("cellb", size)])] + [""] * (n - 1)
                if n > 1:
                    spans.append(("SPAN", (c0, 0), (c0 + n - 1, 0)))
                c0 += n
            data.append(row)
            nhead = 2
        data.append([Paragraph(_pdf_text(header[c]), st[("cellb", size)]) for c in cols])
        for r in rows:
            data.append([Paragraph(marks[r[c]] if (b.marks and r[c] in marks) else _pdf_text(r[c]),
                                   st[("cell", size)]) for c in cols])
        t = RLTable(data, colWidths=colw, repeatRows=nhead, hAlign="LEFT")
        t.setStyle(TableStyle([("GRID", (0, 0), (-1, -1), 0.25, colors.grey),
                               ("BACKGROUND", (0, 0), (-1, nhead - 1), colors.HexColor("#eeeeee")),
                               ("VALIGN", (0, 0), (-1, -1), "TOP"),
                               ("LEFTPADDING", (0, 0), (-1, -1), PAD), ("RIGHTPADDING", (0, 0), (-1, -1), PAD),
                               ("TOPPADDING", (0, 0), (-1, -1), 1), ("BOTTOMPADDING", (0, 0), (-1, -1), 1)]
                              + spans))
        out += [Spacer(1, 4), Paragraph(f"<b>{_pdf_text(title)}</b>", st["cap"]), t]
    if b.note:
        out.append(Paragraph(_pdf_text(b.note), st["small"]))
    if b.source:
        out.append(Paragraph(f"Data: {_pdf_text(b.source)}", st["small"]))
    out.append(Spacer(1, 8))
    return out


FRAME_WIDTH = A4[0] - 32 * mm
FRAME_HEIGHT = A4[1] - 28 * mm


def story(doc: Doc, builder: ReportBuilder) -> list:
    """The report as reportlab flowables (what :func:`render_pdf` lays out; tests measure its tables)."""
    st, unicode_font = _styles()
    width = FRAME_WIDTH
    out = []
    marks = {CHECK: f'<font color="#008800">{CHECK if unicode_font else "ok"}</font>',
             CROSS: f'<font color="#cc0000"><b>{CROSS if unicode_font else "x"}</b></font>',
             NC: '<font color="#cc6600">n.c.</font>'}
    for b in doc.blocks:
        if isinstance(b, Heading):
            if b.new_page:
                out.append(PageBreak())
            target = f'<a name="{b.anchor}"/>' if b.anchor else ""       # where a paragraph's link goes
            out.append(Paragraph(target + _pdf_text(b.text), st["title"] if b.level == 0 else st[min(b.level, 3)]))
        elif isinstance(b, Para):
            text = LINK.sub(lambda m: f'<a href="#{m.group(2)}" color="#1a4f8b">{m.group(1)}</a>', _pdf_text(b.text))
            out.append(Paragraph(text, st.get(b.style, st["p"])))
        elif isinstance(b, Contents):       # links for the HTML; the PDF's readers page through
            continue
        elif isinstance(b, Bullets):
            for i in b.items:
                out.append(Paragraph("- " + _pdf_text(i), st["p"]))
        elif isinstance(b, Figure):
            p = builder.path(b.path)
            with PILImage.open(p) as im:
                w, h = im.size
            scale = min(width / w, 150 * mm / h)
            if b.label == "Fig. R":        # the first page's figure: as large as page 1 allows below the abstract
                scale = min(width / w, 145 * mm / h)
            out.append(KeepTogether([Spacer(1, 4), Image(str(p), width=w * scale, height=h * scale),
                                     Paragraph(f"<b>{_pdf_text(b.label)}</b> {_pdf_text(b.caption)}", st["cap"]),
                                     Spacer(1, 6)]))
        elif isinstance(b, Table):
            out += table_flowables(b, st, width, marks)
    return out


class _Recorder(SimpleDocTemplate):
    """A document template that records on which page each flowable was drawn."""

    def __init__(self, *args, placed=None, **kw):
        super().__init__(*args, **kw)
        self.placed = placed

    def afterFlowable(self, flowable):
        if self.placed is not None:
            self.placed.append((self.page, flowable))


def render_pdf(doc: Doc, builder: ReportBuilder, placed: list | None = None) -> bytes:
    """The report as PDF bytes. ``placed``: a list that receives (page number, flowable) for every flowable drawn
    (what a test reads to know what page 1 holds)."""
    buf = io.BytesIO()
    pdf = _Recorder(buf, pagesize=A4, leftMargin=16 * mm, rightMargin=16 * mm, topMargin=14 * mm,
                    bottomMargin=14 * mm, title="lumbar workflow report", author="lumbar workflow",
                    subject="paper-style report", creator=f"lumbar {__version__}", invariant=1, placed=placed)
    flow = story(doc, builder)
    reg = _FONT["regular"]

    def _page(canvas, _doc):
        canvas.saveState()
        canvas.setFont(reg, 7)
        canvas.drawRightString(A4[0] - 16 * mm, 8 * mm, f"lumbar workflow report - page {canvas.getPageNumber()}")
        canvas.restoreState()

    # binary (Flate) streams without the ASCII85 layer: reportlab encodes ASCII85 in pure Python (its C accelerator
    # is a separate package), which took a quarter of the report job on the figures' pixels; the PDF is 20 % smaller
    a85, rl_config.useA85 = rl_config.useA85, 0
    try:
        pdf.build(flow, onFirstPage=_page, onLaterPages=_page)
    finally:
        rl_config.useA85 = a85
    return buf.getvalue()
