"""The linter: `ruff check` (rules in pyproject.toml [tool.ruff]) passes on the library, the workflow scripts,
the tests and the benchmarks. CI runs it through pytest (.ci/run); ruff is pinned in requirements-test.txt."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PATHS = ("src", "workflow/scripts", "tests", "benchmarks")


def _ruff() -> list[str]:
    exe = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    if exe is None:
        pytest.skip("ruff not installed (pip install -r requirements-test.txt)")
    return [exe]


def test_ruff_check_passes():
    cmd = _ruff() + ["check", "--no-cache", "--output-format", "concise", *PATHS]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stdout[-6000:]}{proc.stderr[-2000:]}"


PROBE = """\
def f():
    import json
    try:
        return json.dumps({})
    except Exception:
        return None
"""


def test_ruff_uses_the_project_config():
    """The rules are the project's (pyproject.toml), not ruff's defaults: a library module with an import in a
    function body and a blind except is flagged for both (PLC0415, BLE001; neither is a ruff default)."""
    cmd = _ruff() + ["check", "--no-cache", "--output-format", "concise", "--stdin-filename",
                     "src/lumbar/_lint_probe.py", "-"]
    proc = subprocess.run(cmd, cwd=ROOT, input=PROBE, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    for rule in ("PLC0415", "BLE001"):
        assert rule in proc.stdout, f"{rule} not reported; ruff output:\n{proc.stdout}{proc.stderr}"
