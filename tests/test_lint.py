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


# ---- snakemake --lint: every rule of the workflow passes Snakemake's own linter (a hard-coded path prefix in params,
# a missing log or conda directive, ...): on a cluster without a shared file system a job reads only its declared
# inputs, so a folder passed as a parameter beside them breaks there (the jobs of workflow/profiles/).
def _snakemake_lint(cwd: Path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakemake", "--lint", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


@pytest.mark.workflow
@pytest.mark.parametrize("config", [(), ("--configfile", "config/test/config.yaml")], ids=["default", "test"])
def test_snakemake_lint_is_clean(config):
    proc = _snakemake_lint(ROOT, *config)
    assert proc.returncode == 0, f"snakemake --lint {' '.join(config)}:\n{proc.stdout[-6000:]}{proc.stderr[-3000:]}"
    assert "Lints for rule" not in proc.stdout + proc.stderr


@pytest.mark.workflow
def test_snakemake_lint_flags_a_hard_coded_prefix(tmp_path):
    """The control: a rule that passes the folder of its input as a parameter is flagged (exit 1)."""
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "a.csv").write_text("x\n1\n")
    (tmp_path / "Snakefile").write_text(
        'rule r:\n    input:\n        "data/a.csv",\n    output:\n        "out.csv",\n    log:\n        "r.log",\n'
        '    params:\n        data_dir="data",\n    shell:\n        "cp {input} {output} 2> {log}"\n')
    proc = _snakemake_lint(tmp_path)
    assert proc.returncode == 1 and "Param data_dir is a prefix of input or output file but hardcoded" in \
        proc.stdout + proc.stderr, proc.stdout + proc.stderr
