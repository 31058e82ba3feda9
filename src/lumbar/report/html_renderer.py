"""HTML renderer of the report: one self-contained file (figures embedded as base64 with their source path in
``data-source``, tables with the CSV they were drawn from)."""
from __future__ import annotations

import base64
import html

from .document import CHECK, CROSS, LINK, NC, Bullets, Contents, Doc, Figure, Heading, Para, Table
from .sections import TITLE, ReportBuilder


CSS = """
*{box-sizing:border-box}
body{font-family:Georgia,'Times New Roman',serif;max-width:60em;margin:1.2em auto;padding:0 1em;line-height:1.45;
color:#111}
nav.toc ol{columns:2;margin:.3em 0 1em;padding-left:1.5em} nav.toc a{text-decoration:none}
div.twrap{max-width:100%;overflow-x:auto;margin:.5em 0 1.5em} div.twrap table{margin:0}
a.csv{font-weight:normal;font-size:.9em;margin-left:.5em}
h1.title{font-size:1.35em;text-align:center;margin:.4em 0} h1{font-size:1.3em;border-bottom:1px solid #999;margin-top:2em}
h2{font-size:1.1em} p.abstract{background:#f4f4f4;padding:.4em .8em;margin:.3em 0} p.small{font-size:.9em;color:#333}
p.note{color:#777;font-style:italic} figure{margin:1.2em 0;text-align:center} figure img{max-width:100%}
figcaption{text-align:left;font-size:.9em} table{border-collapse:collapse;margin:.5em 0 1.5em;font-size:.8em}
td,th{overflow-wrap:normal;word-break:normal;vertical-align:top} td.nw{white-space:nowrap}
caption{caption-side:top;text-align:left;font-weight:bold;padding:.3em 0}
th,td{border:1px solid #bbb;padding:.15em .4em}
th{background:#eee} td.ok{color:#080;text-align:center} td.out{color:#c00;text-align:center;font-weight:bold}
td.nc{color:#c60;text-align:center} div.tnote{font-size:.8em;color:#333;margin-top:-1.2em;margin-bottom:1.5em}
"""


def _h(s) -> str:
    return html.escape(str(s), quote=True)


def _text(s) -> str:
    """A paragraph's text as HTML: escaped, its ``[text](#anchor)`` links as links."""
    return LINK.sub(lambda m: f'<a href="#{m.group(2)}">{m.group(1)}</a>', _h(s))


def render_html(doc: Doc, builder: ReportBuilder) -> str:
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f"<title>{_h(TITLE)}</title>", f"<style>{CSS}</style>", "</head>", "<body>"]
    for b in doc.blocks:
        if isinstance(b, Heading):
            ident = f' id="{_h(b.anchor)}"' if b.anchor else ""
            out.append(f'<h1 class="title"{ident}>{_h(b.text)}</h1>' if b.level == 0 else
                       f"<h{b.level}{ident}>{_h(b.text)}</h{b.level}>")
        elif isinstance(b, Contents):
            out.append('<nav class="toc"><b>Contents</b><ol>' + "".join(f'<li><a href="#{_h(a)}">{_h(t)}</a></li>'
                                                          for t, a in b.items) + "</ol></nav>")
        elif isinstance(b, Para):
            out.append(f'<p class="{b.style}">{_text(b.text)}</p>')
        elif isinstance(b, Bullets):
            out.append("<ul>" + "".join(f"<li>{_h(i)}</li>" for i in b.items) + "</ul>")
        elif isinstance(b, Figure):
            data = base64.b64encode(builder.path(b.path).read_bytes()).decode("ascii")
            out.append(f'<figure><img data-source="{_h(builder.rel_to_html(b.path))}" alt="{_h(b.label)}" '
                       f'src="data:image/png;base64,{data}">'
                       f"<figcaption><b>{_h(b.label)}</b> {_h(b.caption)}</figcaption></figure>")
        elif isinstance(b, Table):
            rel = builder.rel_to_html(b.source) if b.source else None
            src = f' data-source="{_h(rel)}"' if rel else ""
            link = f'<a class="csv" href="{_h(rel)}">[{_h(b.source.rsplit("/", 1)[-1])}]</a>' if rel else ""
            rows = ['<div class="twrap">', f"<table{src}>", f"<caption>{_h(b.title)}{link}</caption>", "<thead>"]
            if b.group_header:
                rows.append("<tr>" + "".join(f'<th colspan="{n}">{_h(t)}</th>' for t, n in b.group_header) + "</tr>")
            rows.append("<tr>" + "".join(f"<th>{_h(h)}</th>" for h in b.header) + "</tr></thead><tbody>")
            for r in b.rows:
                cells = []
                for v in r:
                    cls = {CHECK: "ok", CROSS: "out", NC: "nc"}.get(v) if b.marks else None
                    if cls is None and str(v) and " " not in str(v):
                        cls = "nw"            # one word (a number, "L1-L2", a file name): never broken inside
                    cells.append(f'<td class="{cls}">{_h(v)}</td>' if cls else f"<td>{_h(v)}</td>")
                rows.append("<tr>" + "".join(cells) + "</tr>")
            rows.append("</tbody></table></div>")
            out.append("\n".join(rows))
            if b.note:
                out.append(f'<div class="tnote">{_h(b.note)}</div>')
    out += ["</body>", "</html>", ""]
    return "\n".join(out)
