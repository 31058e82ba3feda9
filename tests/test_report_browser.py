"""The HTML report in a real browser (headless Chromium from Debian, driven by selenium; tests/report_browser.py):
at a 1280 x 800 px viewport the page never scrolls sideways, every image loads, every internal link resolves and the
validation scoreboard figure is on the first screen. Skips with the reason where Chromium, chromedriver or selenium is missing
(.ci/run installs the Debian packages when it runs as root).

Two reports: one built from fixture files (fast lane) and the test-config DAG's (workflow lane: the report the
workflow builds, checked as a reader sees it, first screen included). The report of a run in a checkout is checked
by hand, ``python tests/report_browser.py results/report/paper.html`` (writes ``results/report/first_screen.png``):
a test that needs a run in the checkout would always skip in CI.
"""
from pathlib import Path

import pytest

import report_browser as rb
from test_report import _build, fake_full, fake_png, fake_results  # noqa: F401  (fixtures used here)

ROOT = Path(__file__).resolve().parents[1]
#: how much of the scoreboard figure the first screen (1280 x 800) shows at least: its titles and first rows [px]
FIRST_SCREEN_FIGURE_PX = 200


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
    assert 0 < fig["top"] <= res["viewport"][1] - FIRST_SCREEN_FIGURE_PX
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
    """The report the workflow builds (test config): no problem, its first screen saved, and the scoreboard figure on
    that first screen below title and abstract, the contents linking to the flags."""
    html_path = dag_workdir / "results" / "report" / "paper.html"
    shot = tmp_path / "first_screen.png"
    res = browser.inspect(html_path, shot)
    assert browser.problems(res) == []
    assert res["viewport"][0] == browser.WIDTH and shot.stat().st_size > 0
    fig = next(i for i in res["images"] if i["source"].endswith("validation_scoreboard.png"))
    assert 0 < fig["top"] <= res["viewport"][1] - FIRST_SCREEN_FIGURE_PX, fig
    assert any(link["href"] == "#flags" for link in res["links"])
