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
                           captions_dir=ROOT / "workflow" / "report")
    return out / f"{name}.html", out / f"{name}.pdf", summary


# ----------------------------------------------------------------------------------------------- unit tests
def test_report_references_exist_and_pdf_valid(fake_results):
    html_path, pdf_path, summary = _build(*fake_results)
    refs = check_references(html_path)
    check_pdf(pdf_path)
    assert len(refs.images) == 3 and summary["figures"] + 2 == 3     # Fig. 1, Fig. 6 and one S-figure
    assert any(t.get("data-source") == "../tables/table4_rom_synopsis.csv" for t in refs.tables)


def test_report_numbers_read_from_files(fake_results):
    html_path, _, _ = _build(*fake_results)
    text = parse_report(html_path).text
    assert "17 of 160 (paper: 7 of 160)" in text and "23 of 160 (paper: 47 of 160)" in text
    assert "11 of 49" in text
    assert "Pure moments [2.5, 7.5] N*m" in text                # methods from the config


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
    """workflow/scripts/report.py runs without Snakemake (the _common.stand_in path)."""
    tmp, _, _ = fake_results
    r = subprocess.run([sys.executable, str(ROOT / "workflow" / "scripts" / "report.py"), "paper_report",
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
