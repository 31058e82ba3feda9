"""README.md and docs/ stay true: a short README with the two quick-start commands, and no relative
link in README.md or docs/*.md that points nowhere. Fast; no Snakemake.

Links are Markdown links ``[text](target)`` and reference definitions ``[label]: target`` outside fenced code;
``http(s)``/``mailto`` targets are not checked. A target is resolved relative to the file that holds it and must
exist inside the repository; a ``#fragment`` on a Markdown target must name one of its headings (GitHub's anchor
rule: lower case, punctuation dropped, spaces to hyphens, ``-1``, ``-2`` ... for repeated headings).
"""
import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
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


# ---- docs that cannot go stale: no typed measurement; numbers come from templates rendered by the workflow
TEMPLATES = sorted((DOCS / "templates").glob("*.md"))


def test_docs_type_no_dated_measurement():
    """A number measured once and typed into prose goes stale: README and docs/*.md carry none (no 'recorded at',
    no measurement date, no 'not recorded'); numbers live in the report and in docs/templates/."""
    bad = []
    for path in markdown_files():
        for i, line in _prose_lines(path.read_text()):
            if re.search(r"not recorded|recorded at|\b20\d\d-\d\d-\d\d\b", line, re.I):
                bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()[:100]}")
    assert not bad, "typed measurements in docs:\n" + "\n".join(bad)


def test_doc_templates_read_workflow_outputs():
    """Every placeholder of docs/templates/*.md reads a result file that a rule of the workflow makes (an output
    role of the stage manifests, or a rule's benchmark file; the rule docs_numbers takes them as inputs) and has the
    form 'path | ... | value'."""
    from lumbar.inputs import manifests
    from lumbar.inputs.templates import PLACEHOLDER, template_files

    assert TEMPLATES, "docs/templates/ has no template"
    rules = "".join(p.read_text() for p in (ROOT / "workflow" / "rules").glob("*.smk"))
    declared = {p for m in manifests.MANIFESTS.values() for o in m.outputs.values() for p in o.paths()}
    for t in TEMPLATES:
        text = t.read_text()
        for m in PLACEHOLDER.finditer(text):
            assert len(m.group(1).split("|")) >= 2, f"{t.name}: {m.group(0)}"
        for f in template_files(text):
            assert f.startswith("results/") and f.endswith((".csv", ".tsv", ".json")), f
            bench = re.fullmatch(r"results/benchmarks/(\w+)\.tsv", f)
            made = f in declared or (bench is not None and f'benchmark_file("{bench.group(1)}")' in rules)
            assert made, f"{t.name}: {f} is made by no rule (no manifest role, no benchmark_file)"


def test_template_renderer_reads_values_and_says_what_is_missing(tmp_path):
    from lumbar.report.docs import MISSING, render

    (tmp_path / "t.csv").write_text("set,dir,rom_deg,ok\na,flexion,7.76476,True\nb,flexion,2.3295,False\n"
                                    "a,extension,5.75043,True\n")
    (tmp_path / "m.json").write_text('{"r2": 0.99402917, "n": 4, "sub": {"x": 1.5}}')
    text = ("{{ t.csv | set=a; dir=flexion | rom_deg }} {{ t.csv | ok=True | count }} {{ t.csv | max:rom_deg }} "
            "{{ t.csv | ok=False | list:set }} {{ t.csv | set=c | rom_deg }} {{ m.json | r2 }} {{ m.json | sub.x }} "
            "{{ t.csv | range:rom_deg }}")
    assert render(text, tmp_path) == f"7.76 2 7.76 b {MISSING} 0.994 1.5 2.33 to 7.76"
    with pytest.raises(KeyError, match="no column 'nope'"):
        render("{{ t.csv | nope }}", tmp_path)
    with pytest.raises(FileNotFoundError):
        render("{{ absent.csv | count }}", tmp_path)


@pytest.mark.workflow
def test_rendered_findings_of_the_test_run_are_current(dag_workdir):
    """results/report/<name>.md of the test-config run equals its template rendered now from that run's results:
    the workflow re-renders it whenever a template or a result it reads changes (the rule's inputs)."""
    from lumbar.inputs.templates import PLACEHOLDER
    from lumbar.report.docs import render

    for t in TEMPLATES:
        out = dag_workdir / "results" / "report" / t.name
        text = out.read_text()
        assert "{{" not in text
        body = text.split("\n", 1)[1]
        template = t.read_text()
        assert body == render(template, dag_workdir)
        # independent of the renderer: every placeholder's text in the rendered file is the value read from the
        # result file here with pandas (the template's literal text around it locates it)
        exprs = [m.group(1) for m in PLACEHOLDER.finditer(template)]
        literal = PLACEHOLDER.split(template)[::2]
        pattern = "(.*?)".join(re.escape(part) for part in literal)
        m = re.fullmatch(pattern, body, re.S)
        assert m, f"{out}: the literal text of {t.name} is not where the template has it"
        wrong = [f"{{{{ {e} }}}} rendered {got!r}, the result file says {want}"
                 for e, got in zip(exprs, m.groups()) if not (want := _placeholder_expectation(e, dag_workdir))(got)]
        assert not wrong, "\n".join(wrong)


def _placeholder_expectation(expr: str, root: Path):
    """A predicate on the rendered text of placeholder ``expr``, from the result file read here (pandas, not the
    renderer): counts and text exactly, numbers to the 3 significant digits the renderer prints, rows that do not
    exist in this run as the renderer's stated '(not in this run)'."""
    from lumbar.report.docs import MISSING

    path, *filters, what = [s.strip() for s in expr.split("|")]
    if path.endswith(".json"):
        value = json.loads((root / path).read_text())
        for k in what.split("."):
            if not isinstance(value, dict) or k not in value:
                return _Expect(MISSING, lambda got: got == MISSING)
            value = value[k]
        rows = [value]
        what = None
    else:
        df = pd.read_csv(root / path, sep="\t" if path.endswith(".tsv") else ",")
        for f in filters:
            for cond in (c for c in f.split(";") if c.strip()):
                col, val = (x.strip() for x in cond.split("=", 1))
                df = df[df[col].astype(str) == val]
        if what == "count":
            return _Expect(len(df), lambda got: got == str(len(df)))
        if not len(df):
            return _Expect(MISSING, lambda got: got == MISSING)
        if what.startswith("list:"):
            values = list(dict.fromkeys(df[what[5:]].dropna()))
            return _Expect(values, lambda got: len(got.split(", ")) == len(values) and all(
                _cell_ok(p, v) for p, v in zip(got.split(", "), values)))
        rows = list(df[what]) if ":" not in what else None
        if rows is None:
            agg, col = what.split(":", 1)
            num = pd.to_numeric(df[col])
            rows = [float(num.min()), float(num.max())] if agg == "range" else [float(getattr(num, agg)())]

    def same(got):
        parts = got.split(" to ") if what and what.startswith("range:") else got.split(", ")
        if len(parts) != len(rows):
            return False
        return all(_cell_ok(part, v) for part, v in zip(parts, rows))
    return _Expect(rows, same)


def _cell_ok(part: str, v) -> bool:
    """``part`` shows value ``v``: yes/no for a flag, a number to 3 significant digits, empty for NaN/None."""
    if v is None:
        return part == ""
    if isinstance(v, (bool, np.bool_)):
        return part == ("yes" if v else "no")
    if isinstance(v, (int, float, np.integer, np.floating)):
        if np.isnan(v):
            return part == ""
        return part != "" and math.isclose(float(part), float(v), rel_tol=5e-3, abs_tol=1e-12)
    return part == str(v)


class _Expect:
    def __init__(self, value, check):
        self.value, self.check = value, check

    def __call__(self, got):
        return self.check(got)

    def __str__(self):
        return repr(self.value)
