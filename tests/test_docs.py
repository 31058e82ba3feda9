"""README.md and docs/ stay true (issue 17): a short README with the two quick-start commands, and no relative
link in README.md or docs/*.md that points nowhere. Fast; no Snakemake.

Links are Markdown links ``[text](target)`` and reference definitions ``[label]: target`` outside fenced code;
``http(s)``/``mailto`` targets are not checked. A target is resolved relative to the file that holds it and must
exist inside the repository; a ``#fragment`` on a Markdown target must name one of its headings (GitHub's anchor
rule: lower case, punctuation dropped, spaces to hyphens, ``-1``, ``-2`` ... for repeated headings).
"""
import re
from pathlib import Path

import pytest

from conftest import ROOT

README = ROOT / "README.md"
DOCS = ROOT / "docs"
MAX_README_LINES = 150

#: the two commands of the README's quick start, byte for byte (first: build everything; second: run the tests)
QUICK_START = (
    "python3 -m venv .venv && . .venv/bin/activate && pip install -r environment.txt && pip install -e . "
    "&& snakemake --cores 2",
    "python3 -m venv .venv && . .venv/bin/activate && pip install -r environment.txt -r requirements-test.txt "
    "&& pip install -e . && pytest",
)

_FENCE = re.compile(r"^(```|~~~)")
_INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_REF_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
_CODE_SPAN = re.compile(r"`[^`]*`")


def _prose_lines(text: str):
    """(line number, line) outside fenced code blocks, with inline code spans blanked."""
    fenced = False
    for i, line in enumerate(text.splitlines(), 1):
        if _FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            yield i, _CODE_SPAN.sub("", line)


def relative_links(text: str) -> list[tuple[int, str]]:
    """Every link target of a Markdown text that is not an absolute URL, with its line number."""
    out = []
    for i, line in _prose_lines(text):
        targets = [m.group(1) for m in _INLINE_LINK.finditer(line)]
        m = _REF_DEF.match(line)
        if m:
            targets.append(m.group(1))
        out += [(i, t) for t in targets if not re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", t)]
    return out


def heading_anchors(text: str) -> set[str]:
    """GitHub's anchors of the headings of a Markdown text."""
    seen: dict[str, int] = {}
    anchors = set()
    for _, line in _prose_lines(text.replace("`", "")):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        anchors.add(slug if n == 0 else f"{slug}-{n}")
    return anchors


def broken_links(path: Path, root: Path = ROOT) -> list[str]:
    """Problems with the relative links of one Markdown file ('' list = all good)."""
    problems = []
    for line_no, target in relative_links(path.read_text()):
        where = f"{path.relative_to(root)}:{line_no}: {target}"
        file_part, _, fragment = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path.resolve()
        try:
            dest.relative_to(root.resolve())
        except ValueError:
            problems.append(f"{where} points outside the repository")
            continue
        if not dest.exists():
            problems.append(f"{where} does not exist")
        elif fragment and dest.suffix == ".md" and fragment not in heading_anchors(dest.read_text()):
            problems.append(f"{where}: no heading with anchor #{fragment} in {dest.name}")
    return problems


def markdown_files() -> list[Path]:
    return [README, *sorted(DOCS.glob("*.md"))]


def test_readme_is_short():
    n = len(README.read_text().splitlines())
    assert n <= MAX_README_LINES, f"README.md has {n} lines (at most {MAX_README_LINES}); move detail to docs/"


def test_readme_has_the_two_quick_start_commands():
    lines = README.read_text().splitlines()
    for cmd in QUICK_START:
        assert cmd in lines, f"README.md lost the quick-start command (a line of its own, byte for byte):\n{cmd}"
    assert lines.index(QUICK_START[0]) < lines.index(QUICK_START[1])


def test_readme_keeps_the_resume_command():
    """The 'After an interrupt' paragraph that tests/test_bad_inputs.py runs (there only in the workflow lane)."""
    from test_bad_inputs import _readme_resume_commands
    cmds = _readme_resume_commands()
    assert [c[:2] for c in cmds] == [["snakemake", "--unlock"], ["snakemake", "--workflow-profile"]], cmds


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_to_existing_files(path):
    problems = broken_links(path)
    assert not problems, "broken links:\n" + "\n".join(problems)


def test_readme_links_every_doc():
    linked = {(README.parent / t.partition("#")[0]).resolve() for _, t in relative_links(README.read_text())}
    missing = [p.name for p in sorted(DOCS.glob("*.md")) if p.resolve() not in linked]
    assert not missing, f"docs not linked from README.md ('Where to go next'): {missing}"


# ---- the checker itself can fail
def test_link_checker_reports_broken_links(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("# Title\n\n## Running on a cluster (SLURM)\n")
    md = tmp_path / "README.md"
    md.write_text(
        "[ok](docs/a.md) [ok anchor](docs/a.md#running-on-a-cluster-slurm) [self](#top) [web](https://x.org/y)\n"
        "[missing](docs/b.md) and ![img](fig.png) and [bad anchor](docs/a.md#nowhere)\n"
        "`[in code](nowhere.md)`\n"
        "```\n[in a fence](nowhere.md)\n```\n"
        "[ref]: ../outside.md\n"
        "# Top\n"
    )
    problems = broken_links(md, root=tmp_path)
    assert len(problems) == 4, problems
    assert any("docs/b.md does not exist" in p for p in problems)
    assert any("fig.png does not exist" in p for p in problems)
    assert any("#nowhere" in p for p in problems)
    assert any("outside the repository" in p for p in problems)
