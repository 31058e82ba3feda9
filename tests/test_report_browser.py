"""The HTML report in a real browser (headless Chromium from Debian, driven by selenium; tests/report_browser.py):
at a 1280 px wide window the page never scrolls sideways, every image loads, every internal link resolves and the
validation scoreboard figure is there. Skips with the reason where Chromium, chromedriver or selenium is missing
(.ci/run installs the Debian packages when it runs as root).

Three reports: one built from fixture files (fast lane), the test-config DAG's (workflow lane), and the
repository's own ``results/report/paper.html`` when a run has made one; that case writes
``results/report/first_screen.png``, the first screen a reader sees.
"""
import shutil
from pathlib import Path

import pytest

import report_browser as rb
from test_report import _build, fake_full, fake_png, fake_results  # noqa: F401  (fixtures used here)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def browser():
    why = rb.unavailable()
    if why:
        pytest.skip(f"no browser check: {why}")
    return rb


def test_fixture_report_in_browser(browser, fake_full, tmp_path):  # noqa: F811  (the imported fixture)
    html_path, _, _ = _build(*fake_full)
    res = browser.inspect(html_path, tmp_path / "first_screen.png")
    assert browser.problems(res) == []
    assert res["viewport"][0] == browser.WIDTH
    assert (tmp_path / "first_screen.png").stat().st_size > 0
    # the scoreboard figure starts on the first screen, below title and abstract
    fig = next(i for i in res["images"] if i["source"].endswith("validation_scoreboard.png"))
    assert 0 < fig["top"] < res["viewport"][1]
    assert any(link["href"] == "#flags" for link in res["links"])              # contents -> Flags
    assert any(link["href"].endswith("validation_real_data.csv") and link["file_found"] for link in res["links"])


def test_browser_check_can_fail(browser, tmp_path):
    """A page that scrolls sideways, a broken image, a dangling link, no scoreboard: every problem is named."""
    page = tmp_path / "bad.html"
    page.write_text('<!DOCTYPE html><html><body><div style="width:3000px">wide</div>'
                    '<img data-source="x.png" src="missing.png"><a href="#nowhere">x</a>'
                    '<a href="absent.csv">y</a></body></html>')
    found = browser.problems(browser.inspect(page))
    assert len(found) == 5, found
    assert "scrolls sideways" in found[0]


def test_dag_report_in_browser(browser, dag_workdir, tmp_path):
    html_path = dag_workdir / "results" / "report" / "paper.html"
    res = browser.inspect(html_path, tmp_path / "first_screen.png")
    assert browser.problems(res) == []


def test_repository_report_first_screen(browser):
    """The report of a run in this checkout (skipped before any run): no problem, and its first screen saved as
    results/report/first_screen.png."""
    html_path = ROOT / "results" / "report" / "paper.html"
    if not html_path.is_file():
        pytest.skip("results/report/paper.html not built in this checkout (run snakemake first)")
    shot = html_path.parent / "first_screen.png"
    res = browser.inspect(html_path, shot.with_suffix(".tmp.png"))
    shutil.move(shot.with_suffix(".tmp.png"), shot)
    assert browser.problems(res) == []
