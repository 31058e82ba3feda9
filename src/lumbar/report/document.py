"""The report's document model: the blocks (headings, paragraphs, bullet lists, figures, tables) that the
sections write (:mod:`lumbar.report.sections`) and the renderers draw (:mod:`lumbar.report.html_renderer`,
:mod:`lumbar.report.pdf_renderer`)."""
from __future__ import annotations

import re
from dataclasses import dataclass, field

#: the marks of the check/cross grids (within the reference, outlier, no equilibrium)
CHECK, CROSS, NC = "\u2713", "\u2717", "n.c."
#: a link to a section inside a paragraph's text: ``[text](#anchor)`` (the anchor of a :class:`Heading`); the HTML
#: and the PDF draw it as a link, :func:`plain` as its text
LINK = re.compile(r"\[([^\[\]]+)\]\(#([A-Za-z0-9_-]+)\)")


def plain(text: str) -> str:
    """A paragraph's text as a reader reads it: every ``[text](#anchor)`` as its text."""
    return LINK.sub(lambda m: m.group(1), str(text))


@dataclass
class Heading:
    text: str
    level: int = 1
    anchor: str | None = None      # id of the heading in the HTML (a table of contents or a doc links to it)
    new_page: bool = False         # the PDF starts a new page here


@dataclass
class Para:
    text: str
    style: str = "p"          # p | note | abstract | small


@dataclass
class Bullets:
    items: list


@dataclass
class Figure:
    path: str
    caption: str
    label: str


@dataclass
class Table:
    title: str
    header: list
    rows: list
    source: str | None = None
    note: str = ""
    group_header: list | None = None     # [(text, colspan), ...] drawn above the header
    marks: bool = False                   # cells are check / cross marks
    key_cols: int = 1                     # leading columns repeated in each part when a wide table is split


@dataclass
class Contents:
    """A table of contents: [(text, anchor), ...] (links to headings with that ``anchor``)."""
    items: list


@dataclass
class Doc:
    blocks: list = field(default_factory=list)

    def add(self, *blocks):
        self.blocks.extend(blocks)
