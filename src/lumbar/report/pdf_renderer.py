"""PDF renderer of the report (reportlab, pure Python, ``invariant=1``: no time stamp and a fixed document id,
so the same inputs give the same bytes)."""
from __future__ import annotations

import html
import io
import logging
from pathlib import Path

import matplotlib
from PIL import Image as PILImage
from reportlab.lib import colors
from reportlab.lib.fonts import addMapping
from reportlab.lib.pagesizes import A4
from reportlab.lib.styles import ParagraphStyle, getSampleStyleSheet
from reportlab.lib.units import mm
from reportlab.pdfbase import pdfmetrics
from reportlab.pdfbase.ttfonts import TTFont
from reportlab.platypus import Image, KeepTogether, Paragraph, SimpleDocTemplate, Spacer
from reportlab.platypus import Table as RLTable
from reportlab.platypus import TableStyle

from lumbar import __version__

from .document import CHECK, CROSS, NC, Bullets, Doc, Figure, Heading, Para, Table
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


def render_pdf(doc: Doc, builder: ReportBuilder) -> bytes:

    unicode_font = _register_fonts()
    reg, bold, ital = _FONT["regular"], _FONT["bold"], _FONT["italic"]
    ss = getSampleStyleSheet()
    body = ParagraphStyle("body", parent=ss["BodyText"], fontName=reg)
    st = {
        "title": ParagraphStyle("t", parent=ss["Title"], fontName=bold, fontSize=15, leading=18),
        1: ParagraphStyle("h1", parent=ss["Heading1"], fontName=bold, fontSize=14, keepWithNext=1),
        2: ParagraphStyle("h2", parent=ss["Heading2"], fontName=bold, fontSize=11.5, keepWithNext=1),
        3: ParagraphStyle("h3", parent=ss["Heading3"], fontName=bold, fontSize=10, keepWithNext=1),
        "p": ParagraphStyle("p", parent=body, fontSize=9, leading=11.5),
        "abstract": ParagraphStyle("a", parent=body, fontSize=9, leading=11.5, backColor="#f2f2f2",
                                   borderPadding=3, spaceAfter=6),
        "small": ParagraphStyle("s", parent=body, fontSize=8, leading=10),
        "note": ParagraphStyle("n", parent=body, fontSize=8.5, textColor="#777777", fontName=ital),
        "cap": ParagraphStyle("c", parent=body, fontSize=8, leading=10, keepWithNext=1),
        "cell": ParagraphStyle("cell", parent=body, fontSize=6.5, leading=7.5),
        "cellb": ParagraphStyle("cellb", parent=body, fontSize=6.5, leading=7.5, fontName=bold),
    }
    buf = io.BytesIO()
    pdf = SimpleDocTemplate(buf, pagesize=A4, leftMargin=16 * mm, rightMargin=16 * mm, topMargin=16 * mm,
                            bottomMargin=16 * mm, title="lumbar workflow report", author="lumbar workflow",
                            subject="paper-style report", creator=f"lumbar {__version__}", invariant=1)
    width = A4[0] - 32 * mm
    story = []
    marks = {CHECK: f'<font color="#008800">{CHECK if unicode_font else "ok"}</font>',
             CROSS: f'<font color="#cc0000"><b>{CROSS if unicode_font else "x"}</b></font>',
             NC: '<font color="#cc6600">n.c.</font>'}
    for b in doc.blocks:
        if isinstance(b, Heading):
            story.append(Paragraph(_pdf_text(b.text), st["title"] if b.level == 0 else st[min(b.level, 3)]))
        elif isinstance(b, Para):
            story.append(Paragraph(_pdf_text(b.text), st.get(b.style, st["p"])))
        elif isinstance(b, Bullets):
            for i in b.items:
                story.append(Paragraph("- " + _pdf_text(i), st["p"]))
        elif isinstance(b, Figure):
            p = builder.path(b.path)
            with PILImage.open(p) as im:
                w, h = im.size
            scale = min(width / w, 150 * mm / h)
            story.append(KeepTogether([Spacer(1, 4), Image(str(p), width=w * scale, height=h * scale),
                                       Paragraph(f"<b>{_pdf_text(b.label)}</b> {_pdf_text(b.caption)}", st["cap"]),
                                       Spacer(1, 6)]))
        elif isinstance(b, Table):
            ncol = max(len(b.header), max((len(r) for r in b.rows), default=0))
            cell = st["cell"]
            data = []
            spans = []
            if b.group_header:
                row, c0 = [], 0
                for t, n in b.group_header:
                    row += [Paragraph(_pdf_text(t), st["cellb"])] + [""] * (n - 1)
                    if n > 1:
                        spans.append(("SPAN", (c0, 0), (c0 + n - 1, 0)))
                    c0 += n
                data.append(row)
            data.append([Paragraph(_pdf_text(h), st["cellb"]) for h in b.header])
            for r in b.rows:
                data.append([Paragraph(marks[v] if (b.marks and v in marks) else _pdf_text(v), cell)
                             for v in list(r) + [""] * (ncol - len(r))])
            nhead = 2 if b.group_header else 1
            if b.marks:
                first = 2
                rest = (width - 2 * 22 * mm) / max(ncol - first, 1)
                colw = [22 * mm, 22 * mm] + [rest] * (ncol - first)
            else:
                lens = [max([len(str(b.header[i])) if i < len(b.header) else 1] +
                            [len(str(r[i])) for r in b.rows if i < len(r)]) for i in range(ncol)]
                lens = [min(max(n, 4), 60) for n in lens]
                colw = [width * n / sum(lens) for n in lens]
            t = RLTable(data, colWidths=colw, repeatRows=nhead)
            t.setStyle(TableStyle([("GRID", (0, 0), (-1, -1), 0.25, colors.grey),
                                   ("BACKGROUND", (0, 0), (-1, nhead - 1), colors.HexColor("#eeeeee")),
                                   ("VALIGN", (0, 0), (-1, -1), "TOP"),
                                   ("LEFTPADDING", (0, 0), (-1, -1), 2), ("RIGHTPADDING", (0, 0), (-1, -1), 2),
                                   ("TOPPADDING", (0, 0), (-1, -1), 1), ("BOTTOMPADDING", (0, 0), (-1, -1), 1)]
                                  + spans))
            story += [Spacer(1, 4), Paragraph(f"<b>{_pdf_text(b.title)}</b>", st["cap"]), t]
            if b.note:
                story.append(Paragraph(_pdf_text(b.note), st["small"]))
            story.append(Spacer(1, 8))

    def _page(canvas, _doc):
        canvas.saveState()
        canvas.setFont(reg, 7)
        canvas.drawRightString(A4[0] - 16 * mm, 9 * mm, f"lumbar workflow report - page {canvas.getPageNumber()}")
        canvas.restoreState()

    pdf.build(story, onFirstPage=_page, onLaterPages=_page)
    return buf.getvalue()
