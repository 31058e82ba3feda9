"""The paper-style report (lumbar.report, rule paper_report): every figure and table it references exists and is
non-empty, the PDF is valid, absent stages become "not built in this configuration", surrogate results say so,
numbers come from the files, and the bytes are deterministic.

Unit tests build the report from a few fake result files (fixtures below); ``test_dag_report_*`` check the
report the test-config DAG built (``dag_workdir`` fixture of conftest.py, shared with the other DAG tests).
"""
import base64
import json
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest

from lumbar.inputs.config import load_config
from lumbar.report import NOT_BUILT, build_report

ROOT = Path(__file__).resolve().parents[1]


class _Refs(HTMLParser):
    """Images (data-source, src) and tables (data-source) referenced by the report, and its text."""

    def __init__(self):
        super().__init__()
        self.images, self.tables, self.text = [], [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.images.append(a)
        elif tag == "table":
            self.tables.append(a)

    def handle_data(self, data):
        self.text.append(data)


def parse_report(html_path: Path) -> _Refs:
    p = _Refs()
    p.feed(html_path.read_text(encoding="utf-8"))
    p.text = " ".join(" ".join(p.text).split())
    return p


def check_references(html_path: Path) -> _Refs:
    """Every image and table the HTML references: its file exists and is non-empty, embedded images decode."""
    refs = parse_report(html_path)
    for img in refs.images:
        src = html_path.parent / img["data-source"]
        assert src.is_file() and src.stat().st_size > 0, img["data-source"]
        assert img["src"].startswith("data:image/png;base64,")
        data = base64.b64decode(img["src"].split(",", 1)[1])
        assert data.startswith(b"\x89PNG") and data == src.read_bytes(), img["data-source"]
    for tab in refs.tables:
        if "data-source" in tab:
            src = html_path.parent / tab["data-source"]
            assert src.is_file() and src.stat().st_size > 0, tab["data-source"]
    return refs


def check_pdf(pdf_path: Path):
    data = pdf_path.read_bytes()
    assert data.startswith(b"%PDF-") and data.rstrip().endswith(b"%%EOF")
    assert len(re.findall(rb"/Type\s*/Page[^s]", data)) >= 1
    assert b"/CreationDate (D:20000101000000" in data     # reportlab invariant mode: no time stamp
    # binary Flate streams: the pure-Python ASCII85 layer cost a quarter of the report job (figures' pixels)
    assert b"/FlateDecode" in data and b"ASCII85Decode" not in data


# ----------------------------------------------------------------------------------------------- fixtures
@pytest.fixture
def fake_png():
    def write(path: Path):
        from PIL import Image

        path.parent.mkdir(parents=True, exist_ok=True)
        im = Image.new("RGB", (40, 30), "white")
        for x in range(40):
            im.putpixel((x, x % 30), (200, 0, 0))
        im.save(path)
        return path
    return write


@pytest.fixture
def fake_results(tmp_path, fake_png, monkeypatch):
    """A working directory with a few result files of paper 1 (counts 17 and 23 / 11, surrogate reference)."""
    monkeypatch.chdir(tmp_path)
    t, f = Path("results/tables"), Path("results/figures")
    t.mkdir(parents=True)
    (t / "table4_vs_paper.csv").write_text(
        "set,n_scenarios,n_outliers,paper_n_outliers,paper_source,paper_n_scenarios,our_reference_data\n"
        "calibrated,160,17,7,paper,160,surrogate\nrupp2015,160,23,47,paper,160,surrogate\n")
    (t / "table4_outlier_counts.csv").write_text(
        "set,n_scenarios,n_outliers,n_not_converged,data_kinds\ncalibrated,160,17,0,surrogate\n"
        "rupp2015,160,23,0,surrogate\n")
    (t / "table4_rom_synopsis.csv").write_text(
        "set,stage,direction,moment_nm,rom_sim_deg,rom_mean_deg,rom_min_deg,rom_max_deg,outlier,converged,"
        "data_kind,range_rule\n"
        "calibrated,intact,flexion,1,2.0,1.8,1.6,1.9,True,True,surrogate,min-max\n"
        "calibrated,intact,flexion,2.5,2.5,2.4,2.1,2.7,False,True,surrogate,min-max\n"
        "calibrated,wo_all,flexion,1,,4.9,,,True,False,derived_from_published_fit,mean+-0.5deg\n")
    (t / "table5_outlier_counts.csv").write_text(
        "set,outliers,not_converged,scenarios,data_kind\ncalibrated,11,0,49,surrogate\n")
    (t / "table1_disc_calibrated.csv").write_text(
        "direction,p1_nm,p2_rad3,p3_nm_per_rad,data_kind\nflexion,10.67,0.005913,-1.685,surrogate\n")
    fake_png(f / "fig1_l4l5_model.png")
    fake_png(f / "fig6_rom_stepwise_reduction.png")
    fake_png(f / "muscle_extra_study.png")
    d = Path("data/experiments")
    d.mkdir(parents=True)
    (d / "derived.csv").write_text("stage,rom_mean_deg,kind,source\nwo_all,4.9,derived_from_published_fit,Eq. 3\n")
    config = load_config(ROOT / "config" / "test" / "config.yaml")
    inputs = [str(p) for p in sorted(Path("results").rglob("*")) if p.is_file()] + [str(d / "derived.csv")]
    return tmp_path, config, inputs


@pytest.fixture
def fake_muscle_discrepancy(fake_results, fake_png):
    """Adds the muscle study's metrics and one discovery of the discrepancy workflow to ``fake_results``."""
    tmp, config, inputs = fake_results
    mm = Path("results/muscle_model")
    mm.mkdir(parents=True)
    (mm / "in_vivo_metrics.json").write_text(json.dumps({"r2": 0.9123, "rmse_mpa": 0.0456, "n": 5}))
    dd = Path("results/discrepancy/default")
    dd.mkdir(parents=True)
    (dd / "discovery.json").write_text(json.dumps({
        "named_effect": "disc_tension", "gap_before": 3.25, "gap_after": 0.75, "confidence": 0.875,
        "parameter_estimate": {"parameter": "k_tension", "value": 1234.5, "unit": "N/m"},
        "ranking": [["disc_tension", 10.5], ["none", 42.0]]}))
    fake_png(dd / "ranking.png")
    (dd / "section.md").write_text(
        "## Finding\n\nThe disc carries **tension**.\n\n- gap before: **3.25**\n\n"
        "| rank | effect |\n|---|---|\n| 1 | disc_tension |\n\n![ranking](ranking.png)\n")
    extra = [str(mm / "in_vivo_metrics.json"), str(dd / "discovery.json"), str(dd / "ranking.png"),
             str(dd / "section.md")]
    return tmp, config, inputs + extra


def _build(tmp, config, inputs, name="paper"):
    out = tmp / "results" / "report"
    summary = build_report(inputs, config, out / f"{name}.html", out / f"{name}.pdf",
                           captions_dir=ROOT / "workflow" / "report", logs_dir="logs")
    return out / f"{name}.html", out / f"{name}.pdf", summary


# ----------------------------------------------------------------------------------------------- unit tests
def test_report_references_exist_and_pdf_valid(fake_results):
    html_path, pdf_path, summary = _build(*fake_results)
    refs = check_references(html_path)
    check_pdf(pdf_path)
    from reportlab import rl_config
    assert rl_config.useA85 == 1, "render_pdf left reportlab's global ASCII85 setting changed"
    assert len(refs.images) == 3 and summary["figures"] + 2 == 3     # Fig. 1, Fig. 6 and one S-figure
    assert any(t.get("data-source") == "../tables/table4_rom_synopsis.csv" for t in refs.tables)


def test_report_numbers_read_from_files(fake_results):
    html_path, _, _ = _build(*fake_results)
    text = parse_report(html_path).text
    assert "17 of 160 (paper: 7 of 160)" in text and "23 of 160 (paper: 47 of 160)" in text
    assert "11 of 49" in text
    assert "Pure moments [2.5, 7.5] N*m" in text                # methods from the config


def test_report_methods_name_the_set_of_each_model(fake_results):
    """"Calibrated" is the workflow's own fit in every model; the muscle model's passive set is named by its config
    key. Control: with the published set configured the methods say Table 3, not the workflow's calibration."""
    tmp, config, inputs = fake_results
    text = " ".join(parse_report(_build(tmp, config, inputs)[0]).text.split())
    assert "'Calibrated' means this workflow's own calibration (rule calibrate, tables in " \
           "results/calibration/characteristics" in text
    assert "muscle_model.passive_set = workflow_calibrated): the workflow's calibrated set" in text
    config["muscle_model"]["passive_set"] = "published_table3"
    text = " ".join(parse_report(_build(tmp, config, inputs, "published")[0]).text.split())
    assert "muscle_model.passive_set = published_table3): paper 1's published Table 3 set as printed" in text


def test_report_absent_stages_are_notes_not_errors(fake_results):
    html_path, _, summary = _build(*fake_results)
    text = parse_report(html_path).text
    assert f"Muscle model, in-vivo validation: {NOT_BUILT}" in text
    assert f"Discrepancy workflow: {NOT_BUILT}" in text
    assert f"Fig. 7 (fig7_idp.png): {NOT_BUILT}" in text
    assert any("muscle" not in n.lower() or NOT_BUILT in n for n in summary["not_built"])


def test_report_surrogate_results_are_labelled(fake_results):
    html_path, _, _ = _build(*fake_results)
    html = html_path.read_text()
    caps = re.findall(r"<figcaption>(.*?)</figcaption>", html, re.S)
    fig6 = [c for c in caps if "Fig. 6" in c]
    assert fig6 and "SURROGATE" in fig6[0]
    titles = re.findall(r"<caption>(.*?)</caption>", html, re.S)
    t4 = [c for c in titles if c.startswith("Table 4.")]
    assert t4 and "SURROGATE" in t4[0]
    assert all("surrogate" in c.lower() for c in titles if c.startswith("Table 1."))


def test_report_measured_stepwise_table_is_not_called_surrogate(fake_results):
    """With a measured stepwise table, Table 4 compares with it: the report says so (its outlier-count table's
    header still names the word 'surrogate': the data-kind column decides), and Table 5 keeps its SURROGATE label."""
    tmp, config, inputs = fake_results
    t = Path("results/tables")
    (t / "table4_outlier_counts.csv").write_text(
        "set,n_scenarios,n_outliers,n_not_converged,data_kinds,n_scenarios_real,n_outliers_real,surrogate_comparison\n"
        "calibrated,160,17,0,measured,160,17,none: every reference row is measured or published\n")
    syn = t / "table4_rom_synopsis.csv"
    syn.write_text(syn.read_text().replace(",surrogate,", ",measured,"))
    cfg = {**config, "stepwise_reduction": {**config["stepwise_reduction"], "measured_table": "heuer2007.csv"}}
    text = parse_report(_build(tmp, cfg, inputs)[0]).text
    assert "outliers against the measured reference table: calibrated (this model) 17 of 160" in text
    assert "Table 5 counts outliers against SURROGATE data" in text
    assert "Table 4 and Table 5 count outliers against SURROGATE" not in text


def test_report_muscle_and_discrepancy_sections(fake_muscle_discrepancy):
    html_path, pdf_path, _ = _build(*fake_muscle_discrepancy)
    refs = check_references(html_path)
    check_pdf(pdf_path)
    text = refs.text
    assert "R2 = 0.912" in text and "RMSE = 0.0456 MPa" in text
    assert "disc_tension" in text and "The disc carries tension." in text
    assert "value=1234" in text and "gap before: 3.25" in text and "![ranking]" not in text
    assert any(t.get("data-source", "").endswith("default/section.md") for t in refs.tables)
    assert any(i["data-source"].endswith("discrepancy/default/ranking.png") for i in refs.images)
    assert any(i["data-source"].endswith("muscle_extra_study.png") for i in refs.images)
    assert f"Discovery for case 'in_vivo': {NOT_BUILT}" in text


def test_report_deterministic_bytes(fake_results):
    a = _build(*fake_results, name="a")
    b = _build(*fake_results, name="b")
    assert a[0].read_bytes() == b[0].read_bytes()
    assert a[1].read_bytes() == b[1].read_bytes()


def test_report_script_by_hand(fake_results, tmp_path):
    """workflow/scripts/paper_report.py runs without Snakemake (the _common.stand_in path)."""
    tmp, _, _ = fake_results
    r = subprocess.run([sys.executable, str(ROOT / "workflow" / "scripts" / "paper_report.py"), "paper_report",
                        "--configfile", str(ROOT / "config" / "test" / "config.yaml"),
                        "--output", "results/report/h.html", "results/report/h.pdf"],
                       cwd=tmp, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    check_references(tmp / "results" / "report" / "h.html")
    check_pdf(tmp / "results" / "report" / "h.pdf")


# ----------------------------------------------------------------------------------------------- workflow
def test_snakefmt_check():
    if shutil.which("snakefmt") is None and not (Path(sys.executable).parent / "snakefmt").exists():
        pytest.skip("snakefmt not installed")
    exe = shutil.which("snakefmt") or str(Path(sys.executable).parent / "snakefmt")
    files = ["Snakefile"] + sorted(str(p.relative_to(ROOT)) for p in (ROOT / "workflow" / "rules").glob("*.smk"))
    r = subprocess.run([exe, "--check"] + files, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


def test_dag_report_references_exist(dag_workdir):
    html_path = dag_workdir / "results" / "report" / "paper.html"
    pdf_path = dag_workdir / "results" / "report" / "paper.pdf"
    refs = check_references(html_path)
    check_pdf(pdf_path)
    sources = {i["data-source"] for i in refs.images}
    for fig in ("fig1_l4l5_model", "fig3_l2s1_cables", "fig4_disc_torque_angle", "fig5_ligament_characteristics",
                "fig6_rom_stepwise_reduction", "fig7_idp"):
        assert f"../figures/{fig}.png" in sources, fig
    titles = [c for c in re.findall(r"<caption>(.*?)</caption>", html_path.read_text(), re.S)]
    for n in range(1, 6):
        assert any(c.startswith(f"Table {n}.") for c in titles), n
    assert "Data provenance" in refs.text and "Summary" in refs.text


# ----------------------------------------------------------------------------------------------- first page, tables
VALIDATION_CSV = (
    "quantity,condition,unit,sim,measured,measured_low,measured_high,kind,source,within,tolerance_rule,set,role,note\n"
    # disc-only rows: the same comparison for two sets (shared disc) -> one distinct comparison each
    "L4-L5 ROM,wo_all flexion 1 N*m,deg,4.9298,4.9298,,,derived_from_published_fit,fit,True,measured +- 0.5,"
    "calibrated,calibration target,\n"
    "L4-L5 ROM,wo_all flexion 1 N*m,deg,4.92979,4.9298,,,derived_from_published_fit,fit,True,measured +- 0.5,"
    "rupp2015,calibration target,\n"
    "L4-L5 ROM,wo_all flexion 5 N*m,deg,8.4291,8.4291,,,derived_from_published_fit,fit,True,measured +- 0.5,"
    "calibrated,calibration target,\n"
    "L4-L5 ROM,wo_all flexion 5 N*m,deg,8.4292,8.4291,,,derived_from_published_fit,fit,True,measured +- 0.5,"
    "rupp2015,calibration target,\n"
    "L4-L5 ROM,intact flexion 10 N*m,deg,7.76,8.9,,,original_text,Yamamoto,True,measured +- 25 % (no range published),"
    "calibrated,calibration target,\n"
    "L4-L5 ROM,intact flexion 10 N*m,deg,2.33,8.9,,,original_text,Yamamoto,False,measured +- 25 % (no range published),"
    "paper_table3_as_published,independent,\n"
    "L4-L5 IDP in vivo,crate_far,MPa,,1.8,,,third_party,Wilke,False,no simulated value (no equilibrium),muscle model,"
    "independent,posture not converged\n"
    "L4-L5 IDP in vivo,upright_standing,MPa,0.388,0.5,,,third_party,Wilke,True,measured +- 25 % (no range published),"
    "muscle model,independent,\n"
    "facet joint space width,lumbar (pooled),mm,1.68,1.93,1.42,2.44,third_party,Simon,True,measured range,geometry,"
    "independent,\n")


@pytest.fixture
def fake_full(fake_results, tmp_path):
    """``fake_results`` plus the real-data scoreboard (repeated disc-only rows, a missing simulated value), its
    figure (drawn by the library), a table far wider than the page, and workflow logs with warnings."""
    import pandas as pd

    from lumbar.plots.validation import plot_scoreboard

    tmp, config, inputs = fake_results
    t, f = Path("results/tables"), Path("results/figures")
    (t / "validation_real_data.csv").write_text(VALIDATION_CSV)
    plot_scoreboard(pd.read_csv(t / "validation_real_data.csv"), f / "validation_scoreboard.png")
    cols = [f"structure_{k}_moment_about_the_left_lateral_axis_nm" for k in range(30)]
    wide = pd.DataFrame([[1.23456e-5 * (i + 1) * (k + 1) for k in range(30)] for i in range(12)], columns=cols)
    wide.insert(0, "level", [f"L{i}-L{i + 1}" for i in range(1, 13)])
    wide.to_csv(t / "fsu_geometry.csv", index=False)
    logs = Path("logs")
    (logs / "muscle_sobol_chunk").mkdir(parents=True)
    (logs / "calibrate.log").write_text("2026-01-01 00:00:00,000 INFO lumbar.workflow.calibrate: calibration: 9 steps\n")
    (logs / "muscle_sobol_chunk" / "flexion_1.log").write_text(
        "2026-01-01 00:00:01,000 WARNING lumbar.workflow.muscle_sobol_chunk: Sobol flexion chunk 1: 2 reached "
        "posture(s) whose optimum IPOPT could not certify\n")
    extra = [str(t / "validation_real_data.csv"), str(f / "validation_scoreboard.png"), str(t / "fsu_geometry.csv")]
    return tmp, config, inputs + [e for e in extra if e not in inputs]


def _document(tmp, config, inputs, logs_dir="logs"):
    from lumbar.report import build_document
    return build_document(inputs, config, tmp / "results" / "report" / "paper.html",
                          captions_dir=ROOT / "workflow" / "report", logs_dir=logs_dir)


def pdf_table_problems(doc, builder) -> list[str]:
    """Measured with reportlab on the flowables the PDF is made of: every table fits the frame, and no word of a
    cell is wider than its column (reportlab then never breaks it inside; the cells never split long words)."""
    from reportlab.pdfbase.pdfmetrics import stringWidth
    from reportlab.platypus import Paragraph
    from reportlab.platypus import Table as RLTable

    from lumbar.report.pdf_renderer import FRAME_WIDTH, PAD, story

    out = []
    tables = [f for f in story(doc, builder) if isinstance(f, RLTable)]
    assert tables
    for k, t in enumerate(tables):
        colw = list(t._argW)
        if sum(colw) > FRAME_WIDTH + 0.01:
            out.append(f"table {k}: {sum(colw):.0f} pt wide, frame {FRAME_WIDTH:.0f} pt")
        spans = {(c0, r0): sum(colw[c0:c1 + 1]) for _, (c0, r0), (c1, r1) in t._spanCmds}
        for r, row in enumerate(t._cellvalues):
            for c, (w, cell) in enumerate(zip(colw, row)):
                if not isinstance(cell, Paragraph):
                    continue
                w = spans.get((c, r), w)                         # a group header spans its columns
                assert cell.style.splitLongWords == 0
                for frag in cell.frags:
                    for word in frag.text.split():
                        ww = stringWidth(word, frag.fontName, frag.fontSize)
                        if ww > w - 2 * PAD + 1e-6:
                            out.append(f"table {k}: '{word}' ({ww:.1f} pt) in a {w - 2 * PAD:.1f} pt column")
    return out


def test_first_page_abstract_counts_distinct_comparisons(fake_full):
    html_path, _, _ = _build(*fake_full)
    text = parse_report(html_path).text
    # 9 rows, 7 distinct comparisons: 4 independent (1 within... 2 within), 3 calibration targets (all met)
    assert "7 distinct comparisons with measurements" in text
    assert "Independent checks: 2 of 4 within" in text and "Calibration targets (a fit quality, not a validation): " \
        "3 of 3 met" in text
    assert "misses: L4-L5 ROM (paper's Table 3 set as published) 0 of 1; L4-L5 IDP in vivo 1 of 2." in text
    assert "Table R1. Independent checks (validation): 2 of 4 distinct comparisons within" in text
    assert "Table R2. Calibration targets (fit quality, not validation): 3 of 3 distinct comparisons within" in text
    assert "no value" in text and "2 characteristic sets" in text        # crate_far; the shared disc-only rows
    assert "1 warning(s) need the user's attention" in text
    assert "Sobol flexion chunk 1: 2 reached posture(s)" in text and "muscle_sobol_chunk/flexion_1" in text
    assert "calibration: 9 steps" not in text                              # INFO lines are not flags


def test_pdf_first_page_holds_abstract_and_scoreboard_figure(fake_full):
    from reportlab.platypus import Image, Paragraph

    from lumbar.report import render_pdf
    doc, b = _document(*fake_full)
    placed = []
    render_pdf(doc, b, placed=placed)
    page1 = [f for p, f in placed if p == 1]
    assert any(isinstance(f, Paragraph) and "distinct comparisons" in f.text for f in page1)
    assert any(isinstance(f, Image) and str(f.filename).endswith("validation_scoreboard.png") for f in page1)


def first_page_problems(doc, builder, html_text: str) -> list[str]:
    """What keeps the first page from being one page: more than 250 words before the scoreboard figure (in the HTML,
    lumbar.report.figures_of_record.first_page_words), the figure not on the PDF's page 1 (reportlab's own record of
    where it drew each flowable)."""
    from reportlab.platypus import Image

    from lumbar.report import render_pdf
    from lumbar.report.figures_of_record import FIRST_PAGE_MAX_WORDS, first_page_words
    out = []
    words = first_page_words(html_text)
    if words is None or words > FIRST_PAGE_MAX_WORDS:
        out.append(f"{words} words before the scoreboard figure (at most {FIRST_PAGE_MAX_WORDS})")
    placed = []
    render_pdf(doc, builder, placed=placed)
    pages = [p for p, f in placed if isinstance(f, Image) and str(f.filename).endswith("validation_scoreboard.png")]
    if pages != [1]:
        out.append(f"the scoreboard figure is on PDF page {pages}")
    return out


def test_first_page_is_one_page_with_the_scoreboard_figure(fake_full):
    """At most 250 words before the scoreboard figure and the figure on PDF page 1. Control: the same document with
    the findings that crowded it back before the figure (600 words) fails both."""
    from lumbar.report import render_html
    from lumbar.report.document import Figure, Para
    doc, b = _document(*fake_full)
    assert first_page_problems(doc, b, render_html(doc, b)) == []
    at = next(i for i, x in enumerate(doc.blocks) if isinstance(x, Figure) and x.label == "Fig. R")
    doc.blocks[at:at] = [Para(" ".join(["finding"] * 150), "abstract") for _ in range(4)]
    found = first_page_problems(doc, b, render_html(doc, b))
    assert len(found) == 2 and "words before the scoreboard figure" in found[0] and "PDF page [2]" in found[1], found


def test_first_page_links_the_findings_it_leaves_to_their_sections(fake_full):
    """The first page links the validation section and the flags (and, with internal loads, the posterior section:
    test_dag_report_first_page_is_one_page); the links resolve to the sections' anchors in the HTML and are links in
    the PDF too."""
    html_path, pdf_path, _ = _build(*fake_full)
    html = html_path.read_text()
    first = html[:html.index("validation_scoreboard.png")]
    for anchor in ("validation", "flags"):
        assert f'<a href="#{anchor}">' in first and f'id="{anchor}"' in html, anchor
    assert "](#" not in parse_report(html_path).text                     # no link markup left as text
    assert pdf_path.read_bytes().count(b"/Subtype /Link") >= 2 and b"/Dest [" in pdf_path.read_bytes()   # PDF links


def test_dag_report_first_page_is_one_page(dag_workdir):
    """The test-config DAG's report: at most 250 words before the scoreboard figure in the HTML, and in the PDF
    (pdftotext, Debian's poppler-utils; .ci/run installs it) page 1 holds the figure's caption with at most 250 words
    before it."""
    from lumbar.report.figures_of_record import FIRST_PAGE_MAX_WORDS, first_page_words
    html = (dag_workdir / "results" / "report" / "paper.html").read_text()
    assert first_page_words(html) <= FIRST_PAGE_MAX_WORDS
    first = html[:html.index("validation_scoreboard.png")]
    # the findings the first page leaves to their sections: linked (where the internal loads come from: posterior)
    assert all(f'<a href="#{a}">' in first for a in ("validation", "posterior", "flags")), first[-3000:]
    if shutil.which("pdftotext") is None:
        pytest.skip("pdftotext not found: Debian's poppler-utils package is needed (.ci/run installs it as root)")
    page1 = subprocess.run(["pdftotext", "-f", "1", "-l", "1", str(dag_workdir / "results" / "report" / "paper.pdf"),
                            "-"], capture_output=True, text=True, check=True).stdout
    caption = re.search(r"Fig\. R\s+Validation scoreboard", page1)
    assert caption, page1[:3000]
    before = [w for w in page1[:caption.start()].split() if re.search(r"\w", w)]
    assert len(before) <= FIRST_PAGE_MAX_WORDS, (len(before), page1[:3000])


def test_pdf_tables_never_wrap_a_word_and_fit_the_frame(fake_full):
    doc, b = _document(*fake_full)
    assert pdf_table_problems(doc, b) == []
    # the 31-column geometry table is wider than the page at the smallest font: split, its level column repeated
    from reportlab.platypus import Table as RLTable

    from lumbar.report.pdf_renderer import story
    parts = [f for f in story(doc, b) if isinstance(f, RLTable) and "L1-L2" in str(f._cellvalues[1][0].text)]
    assert len(parts) >= 2


def test_pdf_table_checker_finds_a_word_wider_than_its_column(fake_full):
    """The measurement above can fail: a cell whose one word is wider than the frame."""
    from lumbar.report.document import Table
    doc, b = _document(*fake_full)
    doc.blocks.append(Table("too wide", ["a"], [["x" * 400]]))
    assert any("'xxxx" in p for p in pdf_table_problems(doc, b))


def test_tables_have_human_headers_and_rounded_values(fake_results):
    html_path, _, _ = _build(*fake_results)
    html = html_path.read_text()
    heads = re.findall(r"<th>(.*?)</th>", html)
    assert "p3 [N·m/rad]" in heads and "ROM simulated [deg]" not in heads   # table1; table4 synopsis is a grid
    assert "p3_nm_per_rad" not in heads and "-1.69" in html and "-1.685" not in html
    assert "0.00591" in html                                                  # 3 significant digits


def test_report_sections_can_be_added_from_outside(fake_results):
    from lumbar.report import SECTIONS, report_section

    before = list(SECTIONS)
    try:
        @report_section("load-sharing", "Load sharing between disc, facets and ligaments", after="idp")
        def _load_sharing(b):
            b.para("Load sharing: read from a result file.")
            b.csv_table("results/load_sharing/absent.csv", "Load sharing per structure")
        html_path, _, _ = _build(*fake_results)
        text = parse_report(html_path).text
        anchors = [s.anchor for s in SECTIONS]
        assert anchors.index("load-sharing") == anchors.index("idp") + 1
        numbered = [s.anchor for s in SECTIONS if s.numbered]
        n = numbered.index("load-sharing") + 1
        assert numbered[n - 2] == "idp"
        assert f"{n} Load sharing between disc, facets and ligaments" in text     # numbered right after the IDP
        assert f"Load sharing per structure (absent.csv): {NOT_BUILT}" in text
        assert 'href="#load-sharing"' in html_path.read_text()
        with pytest.raises(ValueError, match="no section"):
            report_section("x", "X", after="nowhere")(lambda b: None)
    finally:
        SECTIONS[:] = before


@pytest.mark.workflow
def test_dag_report_pdf_tables_and_scoreboard_page(dag_workdir, monkeypatch):
    """The test-config DAG's report: every PDF table fits the frame without a word wrapped inside, and Tables R1
    and R2 together fit one page at the largest cell font."""
    from reportlab.platypus import Paragraph
    from reportlab.platypus import Table as RLTable

    from lumbar.report.pdf_renderer import CELL_SIZES, FRAME_HEIGHT, FRAME_WIDTH, story
    monkeypatch.chdir(dag_workdir)
    inputs = [str(p) for p in sorted(Path("results").rglob("*")) if p.is_file() and "report" not in p.parts]
    inputs += [str(p) for p in sorted(Path("data").rglob("*.csv"))]
    doc, b = _document(dag_workdir, load_config(dag_workdir / "config" / "test" / "config.yaml"), inputs)
    assert pdf_table_problems(doc, b) == []
    flow = story(doc, b)
    r = [(i, f) for i, f in enumerate(flow) if isinstance(f, RLTable) and i > 0 and isinstance(flow[i - 1], Paragraph)
         and re.match(r"<b>Table R[12]\.", flow[i - 1].text)]
    assert len(r) == 2
    assert all(f._cellvalues[1][1].style.fontSize == CELL_SIZES[0] for _, f in r)    # the largest cell font
    height = sum(f.wrap(FRAME_WIDTH, FRAME_HEIGHT)[1] + 30 for _, f in r)      # + title and spacing
    assert height < FRAME_HEIGHT


def test_real_data_paragraph_keeps_unexplained_apart_from_nothing_named(fake_results):
    """A real dataset the discovery calls "unexplained" (the data differ, no library effect or nuisance explains it)
    is not summed up as "nothing named" on the first lines of the section: the user must act on it."""
    tmp, config, inputs = fake_results
    p = Path("results/discrepancy/real_data_summary.csv")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("dataset,n_rows,gap_before,named_effect,p_value,estimate,gap_after,decision,best_nuisance,"
                 "nuisance_p_value,gap_specimen_mean,gap_nuisance,note\n"
                 "intact_rom,4,7.07,,0.005,,7.07,unexplained,uniform offset,0.005,6.9,6.4,x\n"
                 "in_vivo,4,1.55,,0.945,,1.55,nothing named,nominal model,,1.55,1.55,y\n")
    html_path, _, _ = _build(tmp, config, inputs + [str(p)])
    text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html_path.read_text()))
    assert re.search(r"Tested, unexplained \([^)]*\): intact_rom \(gap 7\.07\)", text), text[:2000]
    assert re.search(r"Tested, nothing named \([^)]*\): in_vivo \(gap 1\.55\)", text)
    assert not re.search(r"nothing named[^.]*intact_rom", text)


def test_muscle_sentence_names_reached_but_uncertified_apart_from_not_reached(fake_muscle_discrepancy):
    """The first page counts the activities with a certified optimum and names a posture that was reached but whose
    optimum IPOPT could not certify apart from one the muscles cannot reach (beyond their capacity)."""
    tmp, config, inputs = fake_muscle_discrepancy
    t = Path("results/tables")
    (t / "in_vivo_validation.csv").write_text(
        "activity,idp_sim_mpa,idp_in_vivo_mpa,converged,reached,certified\n"
        "upright_standing,0.43,0.5,False,True,False\n"
        "crate_far,0.64,1.8,False,False,False\n"
        "flexion_36deg,0.93,1.08,True,True,True\n")
    extra = [str(t / "in_vivo_validation.csv")]
    html_path, _, _ = _build(tmp, config, inputs + [e for e in extra if e not in inputs])
    text = parse_report(html_path).text
    assert "activities with a certified optimum" in text
    assert "reached, but IPOPT could not certify the optimum (left out; Flags): upright standing" in text
    assert "not reached (beyond its muscles' capacity; muscle capacity table): crate far" in text
    # control: the uncertified posture is not called "not reached", nor the unreached one "reached"
    assert "muscle capacity table): upright standing" not in text
    assert "(left out; Flags): crate far" not in text
    # without the metrics of the reached activities, no such clause
    assert "activities reached: R2" not in text


def test_muscle_sentence_gives_the_fit_with_the_reached_but_uncertified_posture(fake_muscle_discrepancy):
    """Where a reached posture is left out for its certificate, the first page also gives R2 and RMSE over every
    reached activity (the metrics' r2_reached), so that a reader sees what the left-out posture would change."""
    tmp, config, inputs = fake_muscle_discrepancy
    t = Path("results/tables")
    (t / "in_vivo_validation.csv").write_text(
        "activity,idp_sim_mpa,idp_in_vivo_mpa,converged,reached,certified\n"
        "upright_standing,0.43,0.5,False,True,False\n"
        "flexion_36deg,0.93,1.08,True,True,True\n")
    mm = Path("results/muscle_model")
    (mm / "in_vivo_metrics.json").write_text(json.dumps(
        {"r2": 0.5037, "rmse_mpa": 0.2052, "n": 3, "n_total": 5, "r2_reached": 0.7223, "rmse_reached_mpa": 0.1811,
         "n_reached": 4}))
    extra = [str(t / "in_vivo_validation.csv")]
    html_path, _, _ = _build(tmp, config, inputs + [e for e in extra if e not in inputs])
    text = parse_report(html_path).text
    assert re.search(r"upright standing \(with it, over the 4 activities reached: R2 = 0\.72\d*, RMSE = 0\.18\d* MPa\)",
                     text), text[:3000]


def test_posterior_judged_sentence_reads_the_draws_and_says_whether_the_data_decide():
    """The share of posterior draws meeting the judged limits (extension facet force <= 90.5 N, SSL >= 5 N), from
    the draws' values of the band rule; control: draws that meet both say the data do not decide them."""
    import pandas as pd

    from lumbar.report.influence_text import posterior_judged_sentence
    from lumbar.report.sections import fmt

    def table(fac, ssl):
        rows = [("extension", 7.5, "facet_max_contact_n", i, v) for i, v in enumerate(fac)]
        rows += [("flexion", 10.0, "SSL_tension_n", i, v) for i, v in enumerate(ssl)]
        return pd.DataFrame(rows, columns=["direction", "moment_nm", "quantity", "draw", "value"])

    s = posterior_judged_sentence(table([80, 120, 130, 140], [6, 2, 3, 7]), fmt)
    assert "Of 4 posterior draws, 25 % keep" in s and "at 10 N*m flexion, 25 % both" in s
    assert "50 % give the SSL at least 5 N at 10 N*m flexion" in s and "do not decide" in s
    s = posterior_judged_sentence(table([120] * 20, [6] * 20), fmt)
    assert "0 % both" in s and "improbable" in s
    assert posterior_judged_sentence(table([], []), fmt) == "" and posterior_judged_sentence(None, fmt) == ""


def test_first_page_says_in_words_which_trivial_model_the_model_does_not_beat():
    """The null-model table in words: the model's count once per quantity beside every trivial model's, and which
    one it does not beat (control: a quantity where the model beats its null says nothing of the kind)."""
    import pandas as pd

    from lumbar.report.sections import null_models_sentence

    t = pd.DataFrame({"quantity": ["ROM, other levels", "ROM, other levels", "L4-L5 IDP in vivo"],
                      "null_model": ["a", "b", "c"], "description": ["copy A", "copy B", "the mean"],
                      "n_rows": [16, 16, 5], "model_within": [12, 12, 3], "null_within": [9, 13, 2],
                      "model_beats_null": [True, False, True]})
    s = null_models_sentence(t)
    assert s.count("12 of 16 within") == 1 and "against 9 (copy A) and 13 (copy B)" in s
    assert "does not beat the trivial model at 13" in s
    assert "3 of 5 within against 2 (the mean)" in s and s.count("does not beat") == 1      # control
    assert "which it does not beat" in null_models_sentence(t.iloc[2:].assign(model_beats_null=False))
    assert null_models_sentence(t.iloc[:0]) == ""


def test_first_page_puts_the_trivial_models_counts_beside_the_models():
    """The first page's short form of the null-model table: the trivial models' counts beside the model's own count
    of the quantity, and how many of them the model beats (control: a quantity without a trivial model gets none)."""
    import pandas as pd

    from lumbar.report.sections import null_models_brief, trivial_counts

    t = pd.DataFrame({"quantity": ["ROM, other levels", "ROM, other levels", "L4-L5 IDP in vivo"],
                      "null_model": ["a", "b", "c"], "description": ["copy A", "copy B", "the mean"],
                      "n_rows": [16, 16, 5], "model_within": [12, 12, 3], "null_within": [9, 13, 2],
                      "model_beats_null": [True, False, True]})
    assert trivial_counts(t, "ROM, other levels") == " (trivial models: 9, 13)"
    assert trivial_counts(t, "L4-L5 IDP in vivo") == " (trivial model: 2)"
    assert trivial_counts(t, "facet joint space width") == "" and trivial_counts(None, "x") == ""
    assert null_models_brief(t) == "It beats 2 of 3 trivial models on the same rows."
    assert null_models_brief(t.iloc[:0]) == ""


def test_contact_sentence_reads_the_joints_once_and_apart_at_the_lumbosacral_level():
    import pandas as pd

    from lumbar.report.landmark_accuracy_section import contact_sentence
    f = pd.DataFrame(dict(level=["L3-L4", "L3-L4", "L4-L5", "L4-L5", "L5-S1"],
                          side=["left", "left", "right", "right", "left"], face=["superior", "inferior"] * 2 + ["inferior"],
                          contact_normal_angle_deg=[6.0, 6.0, 14.0, 14.0, 23.0]))
    s = contact_sentence(f)
    assert "6-14 deg above L5-S1" in s and "23 deg at L5-S1" in s
    assert contact_sentence(f.drop(columns="contact_normal_angle_deg")) == ""    # an older table: no sentence


def test_internal_load_checks_say_when_they_cannot_fail_for_a_missing_load():
    """An acceptance interval down to zero (an in-vitro mean - 2 SD below 0) passes a load the model does not carry;
    the tables count such rows and give the ratio to the measured mean; control: an interval above zero is not
    counted."""
    import numpy as np
    import pandas as pd

    from lumbar.experiments import validation as V
    rows = pd.DataFrame(dict(band_low=[0.0, -3.0, 10.0, np.nan]))
    assert V.zero_floor_count(rows) == 2
    assert V.mean_ratio(115.0, 51.5) == pytest.approx(2.233, abs=1e-3)
    assert np.isnan(V.mean_ratio(1.0, 0.0)) and np.isnan(V.mean_ratio(np.nan, 3.0))


def test_voxelised_landmark_rows_and_sentence_read_each_input_once():
    """Table G2 and its sentence: one row per input (surface meshes first, then each voxel edge), the groups' and
    facet faces' distances read from the table; no label volume, no sentence."""
    import pandas as pd

    from lumbar.report.landmark_accuracy_section import voxelised_rows, voxelised_sentence
    structures = ["all ligament groups", "facet faces vs their bone points", "facet faces vs cartilage nodes"]
    t = pd.DataFrame(dict(input=["surface meshes"] * 3 + ["label volume"] * 6,
                          voxel_mm=[float("nan")] * 3 + [1.0] * 3 + [1.5] * 3, structure=structures * 3,
                          n_groups=[81, 18, 18] * 3, median_mm=[1.53, 0.77, 1.27, 1.43, 0.98, 1.62, 1.46, 0.77, 1.58],
                          max_mm=[6.8, 1.8, 2.1, 7.3, 2.6, 3.0, 7.1, 2.6, 2.9],
                          facet_surfaces_supported=[True] * 3 + [False] * 6))
    rows = voxelised_rows(t)
    assert [r[0] for r in rows] == ["surface meshes", "label volume, 1 mm voxels", "label volume, 1.5 mm voxels"]
    assert rows[1][1:] == ["1.4", "7.3", "0.98", "2.6", "1.6", "no"] and rows[0][-1] == "yes"
    s = voxelised_sentence(t)
    assert "voxelised at 1 and 1.5 mm" in s and "a median 1.4-1.5 mm from the reference (surface meshes: 1.5 mm)" in s
    assert "0.77-0.98 mm from their bone points" in s
    assert voxelised_sentence(t[t["input"] == "surface meshes"]) == ""


def test_first_page_of_a_specimen_run_names_it_and_shows_its_landmark_qa(fake_full):
    """A user's specimen (geometry kind meshes): the first page names the specimen, its units and what its facets
    rest on, and shows the calibrated unit's landmark QA figure; the methods do not call it the myo-sim meshes.
    Control: the Visible Human run's first page has no specimen paragraph."""
    import copy

    import pandas as pd
    from matplotlib.figure import Figure

    tmp, config, inputs = fake_full
    default_text = parse_report(_build(tmp, config, inputs, name="default")[0]).text
    assert "Specimen:" not in default_text
    g = Path("results/geometry")
    g.mkdir(parents=True, exist_ok=True)
    pd.DataFrame({"level": ["L3-L4", "L4-L5"], "disc_height_mm": [8.04, 10.6],
                  "facet_numbers": ["measured from the surfaces", "not supported: voxels of 3 mm."]}).to_csv(
        g / "levels.csv", index=False)
    fig = Figure(figsize=(2, 2))
    fig.add_subplot().plot([0, 1], [0, 1])
    fig.savefig(g / "qa_L4-L5.png")
    spec = copy.deepcopy(config)
    spec["geometry"] = {"kind": "meshes", "path": "/data/spec12/stl", "units": "mm", "axes": "LPS"}
    html, _, _ = _build(tmp, spec, inputs + [str(g / "levels.csv"), str(g / "qa_L4-L5.png")], name="spec")
    text = parse_report(html).text
    assert "Specimen: stl (vertebra surfaces, /data/spec12/stl; mm, LPS axes)" in text
    assert "Units built: L3-L4, L4-L5 (endplate disc heights 8-11 mm)" in text
    assert "Facet joints: not supported: voxels of 3 mm." in text
    assert "Fig. Q" in text and "qa_L4-L5.png" in html.read_text()
    assert "myo-sim meshes" not in text and "a user's specimen: vertebra surfaces" in text


def test_first_page_names_internal_loads_in_the_upper_tail_of_the_measured_spread():
    """A row within mean +- 2 SD but above the mean + 1 SD is named with its value and the mean; one within 1 SD, one
    outside the tolerance and one judged by another rule are not (control)."""
    import pandas as pd  # noqa: PLC0415

    from lumbar.report.sections import above_one_sd  # noqa: PLC0415
    rows = pd.DataFrame({
        "quantity": ["facet contact force per joint"] * 3 + ["ISL + SSL force"],
        "condition": ["extension, 7.5 N*m", "flexion, 7.5 N*m", "axial rotation, 7.5 N*m", "flexion, 10 N*m"],
        "unit": ["N"] * 4, "sim": [115.0, 60.0, 200.0, 130.0], "measured": [51.5, 46.1, 70.3, 134.0],
        "measured_high": [129.5, 128.7, 156.7, 134.0], "within": [True, True, False, True],
        "tolerance_rule": ["mean +- 2 SD (in vitro)"] * 3 + ["measured range"]})
    assert above_one_sd(rows) == ["facet contact force per joint, extension 7.5 N\u00b7m 115 N against 51.5"]
