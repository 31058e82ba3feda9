"""The report as a reader sees it: ``paper.html`` in headless Chromium (Debian's ``chromium`` and
``chromium-driver``, driven by selenium; never a downloaded browser) at a 1280 px wide window.

Used by tests/test_report_browser.py, and by hand after a run (writes ``first_screen.png`` beside the report)::

    python tests/report_browser.py results/report/paper.html

``inspect(html)`` returns what the test asserts: the horizontal overflow of the page [px], every image (its
``data-source``, whether it loaded, its natural width), every link and whether its target exists (an ``#id`` in
the page, or a file next to the report), whether the scoreboard figure is there and where, and the viewport
size. The screenshot is of the first screen (a 1280 x 800 px viewport).
"""
from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path
from urllib.parse import unquote, urlparse

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
WIDTH, HEIGHT = 1280, 800
#: Chromium as root in a sandbox-less container: no sandbox, no GPU, no network services of its own
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", f"--window-size={WIDTH},{HEIGHT}")


def unavailable() -> str | None:
    """Why the browser check cannot run here (None when it can)."""
    try:
        import selenium  # noqa: F401, PLC0415
    except ImportError:
        return "the selenium package is not installed (requirements-test.txt)"
    for exe, pkg in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not exe.is_file():
            return (f"{exe} not found: Debian's {pkg} package is needed (apt-get install chromium chromium-driver; "
                    ".ci/run installs them when it runs as root)")
    return None


_JS = """
const out = {};
const de = document.documentElement;
out.viewport = [window.innerWidth, window.innerHeight];
out.overflow_x = Math.max(de.scrollWidth, document.body.scrollWidth) - de.clientWidth;
out.images = Array.from(document.images).map(i => ({source: i.getAttribute('data-source'), complete: i.complete,
  width: i.naturalWidth, top: i.getBoundingClientRect().top}));
out.links = Array.from(document.querySelectorAll('a[href]')).map(a => ({href: a.getAttribute('href'),
  url: a.href, id_found: a.getAttribute('href').startsWith('#') ?
    document.getElementById(decodeURIComponent(a.getAttribute('href').slice(1))) !== null : null}));
const wide = [];
document.querySelectorAll('table').forEach(t => { const r = t.getBoundingClientRect();
  if (r.right > de.clientWidth + 0.5) wide.push(t.querySelector('caption') ? t.querySelector('caption').innerText : '?'); });
out.beyond_viewport = wide;
return JSON.stringify(out);
"""


def inspect(html: Path, screenshot: Path | None = None) -> dict:
    """Open ``html`` at 1280 px and measure it (see the module docstring); save the first screen to
    ``screenshot``. Link targets that are files are resolved next to ``html`` and checked on disk."""
    from selenium import webdriver  # noqa: PLC0415
    from selenium.webdriver.chrome.service import Service  # noqa: PLC0415

    html = Path(html).resolve()
    profile = tempfile.mkdtemp(prefix="chromium-profile-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for f in FLAGS + (f"--user-data-dir={profile}",):
        opts.add_argument(f)
    driver = webdriver.Chrome(service=Service(executable_path=str(CHROMEDRIVER)), options=opts)
    try:
        driver.set_window_size(WIDTH, HEIGHT)
        # the page's viewport itself 1280 x 800 (a window of that size leaves less to the page: its own bars)
        driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {"width": WIDTH, "height": HEIGHT,
                                                                      "deviceScaleFactor": 1, "mobile": False})
        driver.get(html.as_uri())
        out = json.loads(driver.execute_script(_JS))
        if screenshot is not None:
            Path(screenshot).parent.mkdir(parents=True, exist_ok=True)
            driver.save_screenshot(str(screenshot))
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
    for link in out["links"]:
        if link["id_found"] is None:
            u = urlparse(link["url"])
            link["file_found"] = u.scheme == "file" and Path(unquote(u.path)).is_file()
    return out


def problems(result: dict) -> list[str]:
    """What a reader would trip over, from :func:`inspect`'s result ('' list = none)."""
    out = []
    if result["overflow_x"] > 0:
        out.append(f"the page scrolls sideways by {result['overflow_x']} px at {WIDTH} px "
                   f"(tables beyond the viewport: {result['beyond_viewport']})")
    for img in result["images"]:
        if not img["complete"] or img["width"] == 0:
            out.append(f"image not loaded: {img['source']}")
    for link in result["links"]:
        if link["id_found"] is False or link.get("file_found") is False:
            out.append(f"link target missing: {link['href']}")
    if not any(str(i["source"]).endswith("validation_scoreboard.png") for i in result["images"]):
        out.append("the validation scoreboard figure is not in the report")
    return out


if __name__ == "__main__":
    why = unavailable()
    if why:
        raise SystemExit(why)
    page = Path(sys.argv[1] if len(sys.argv) > 1 else "results/report/paper.html")
    res = inspect(page, page.parent / "first_screen.png")
    print(json.dumps({k: v for k, v in res.items() if k != "links"}, indent=1))
    bad = problems(res)
    print("\n".join(bad) or f"ok: no overflow at {WIDTH} px, {len(res['images'])} images, {len(res['links'])} links")
    raise SystemExit(1 if bad else 0)
