"""Shared fixtures: a hand-built characteristic set (paper 1 Tables 1 and 3), paths, and
``dag_workdir``: the whole default DAG run once per session on config/test in a copy of the repository."""
import importlib.util
import shutil
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace as NS

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
VISIBLE_HUMAN = SHARED / "geometry" / "visible_human_lss"

TABLE1 = {"flexion": (10.67, 0.005913, -1.685), "extension": (5.196, 0.008417, 24.50),
          "lateral_bending": (6.929, 0.001482, 19.76), "axial_rotation": (4.399, 0.001141, 42.38)}


def make_charset(torque=None, ligaments=True, facet_stiffness=12000.0, k_shear=9.65e4):
    disc = NS(k_axial_quadratic=690234060.0, k_axial_linear=659748.0, k_shear=k_shear, k_tension=0.0,
              torque=torque or TABLE1)
    L = lambda a, b, c, d, p: NS(a=a, b=b, c=c, d=d, prestrain_pct=p)  # noqa: E731
    ligs = {"ALL": L(173.5, -10.06, -26.82, 5.625, 8), "PLL": L(48.12, -43.97, -2.5, 15, 10),
            "FL": L(47.11, 4.21, 54.85, -11.25, 10), "CL": L(98.94, 18.97, -82.2, 73.33, 10),
            "ISL": L(0.4517, -3.502, 0, 0.02414, 4), "SSL": L(1.218, -22.97, 0, 1.369, -6)}
    return NS(name="test", disc=disc, facet=NS(stiffness=facet_stiffness), ligaments=ligs if ligaments else {})


@pytest.fixture
def charset():
    return make_charset()


@pytest.fixture
def shared_geometry_dir():
    if not VISIBLE_HUMAN.is_dir():
        pytest.skip("../shared/geometry/visible_human_lss not present")
    return VISIBLE_HUMAN


# ---------------------------------------------------------------- the workflow DAG, once per session
TEST_CONFIG = "config/test/config.yaml"
COPY_IGNORE = shutil.ignore_patterns(".git", "results", ".snakemake", "logs", ".venv", "__pycache__",
                                     ".pytest_cache", ".hypothesis", "*.egg-info", "report.zip")


def copy_repo(dest: Path) -> Path:
    """A throw-away copy of the repository (no .git, results, .snakemake, logs, .venv) at ``dest``."""
    shutil.copytree(ROOT, dest, ignore=COPY_IGNORE, symlinks=True)
    return dest


def snakemake(*args, cwd, timeout=1500) -> subprocess.CompletedProcess:
    """``python -m snakemake *args`` in ``cwd`` (captured text output)."""
    return subprocess.run([sys.executable, "-m", "snakemake", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)


def _dag_failed(workdir: Path, rc: int, out: str):
    logs = "".join(f"\n==> {p.name}\n" + p.read_text()[-3000:]
                   for p in sorted((workdir / "logs").glob("*.log"))) if (workdir / "logs").exists() else ""
    pytest.fail(f"snakemake failed in {workdir} (exit {rc})\n{out[-12000:]}{logs}", pytrace=False)


def run_dag(workdir: Path, *extra) -> subprocess.CompletedProcess:
    """The default target ``all`` on config/test with 2 cores; fails the test with the logs if it fails.
    Snakemake's output is kept in ``<workdir>/dag_run.out`` (with the wall time in seconds)."""
    t0 = time.perf_counter()
    r = snakemake("--cores", "2", "--configfile", TEST_CONFIG, *extra, cwd=workdir)
    (workdir / "dag_run.out").write_text(f"# {time.perf_counter() - t0:.1f} s\n" + r.stdout + r.stderr)
    if r.returncode != 0:
        _dag_failed(workdir, r.returncode, r.stdout + r.stderr)
    return r


def _need_snakemake():
    if importlib.util.find_spec("snakemake") is None:
        pytest.skip("snakemake is not installed")


_SECOND_DAG = {}   # the reproducibility run, started beside the first when that test is collected


@pytest.fixture(scope="session")
def dag_workdir(tmp_path_factory, request) -> Path:
    """Path of a copy of the repository in which ``snakemake --cores 2 --configfile config/test/config.yaml``
    (the whole default target ``all``) has run successfully. Read-only for tests: copy what you modify.

    When tests/test_dag.py's reproducibility test is collected, its second run (another fresh copy) starts
    at the same time, so the two runs fill each other's idle core (the DAG has long serial chains)."""
    _need_snakemake()
    work = copy_repo(tmp_path_factory.mktemp("dag") / "repo")
    if any(item.name == "test_dag_reproducible_byte_identical" for item in request.session.items):
        second = copy_repo(tmp_path_factory.mktemp("dag2") / "repo")
        log = open(second / "dag_run.out", "w")
        proc = subprocess.Popen([sys.executable, "-m", "snakemake", "--cores", "2", "--configfile", TEST_CONFIG],
                                cwd=second, stdout=log, stderr=subprocess.STDOUT, text=True)
        _SECOND_DAG.update(path=second, proc=proc, log=log, t0=time.perf_counter())

        def stop_second():          # e.g. the first run failed: do not leave the second one running
            if proc.poll() is None:
                proc.terminate()
                proc.wait(timeout=60)
            log.close()
        request.addfinalizer(stop_second)
    run_dag(work)
    return work


@pytest.fixture(scope="session")
def dag_second_workdir(dag_workdir, tmp_path_factory) -> Path:
    """A second, independent run of the same DAG in another fresh copy (for the reproducibility test)."""
    if not _SECOND_DAG:
        second = copy_repo(tmp_path_factory.mktemp("dag2") / "repo")
        run_dag(second)
        return second
    proc, second = _SECOND_DAG["proc"], _SECOND_DAG["path"]
    try:
        rc = proc.wait(timeout=1500)
    finally:
        _SECOND_DAG["log"].close()
    if rc != 0:
        _dag_failed(second, rc, (second / "dag_run.out").read_text())
    return second
