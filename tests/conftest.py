"""Shared fixtures: the real characteristic sets (``lumbar.inputs.characteristics``) with overrides, paths, and
``dag_workdir``: the whole default DAG run once per session on config/test in a copy of the repository.

Markers (pyproject.toml): every test that uses the session DAG (``dag_workdir``, ``dag_second_workdir`` or a
fixture built on them) is marked ``workflow`` here, so the fast lane ``pytest -m "not workflow and not slow"``
never starts Snakemake.
"""
# ruff: noqa: E402 - the thread variables below are set before numpy is imported
import os

# One BLAS/OpenMP thread per test process, as every Snakemake job gets (workflow/scripts/_common.py): the tests' numbers
# are then the jobs' (the last digits of a multithreaded BLAS differ), and two xdist workers beside the background
# Snakemake runs on two cores do not each start BLAS threads that wait spinning for a core. Set before numpy is
# imported; a value already in the environment is kept.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
              "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import atexit
import dataclasses
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from hypothesis import settings as _hypothesis_settings

# Property tests draw the same examples on every run (a failure is a finding that reproduces, not a flake of the
# random seed): ``HYPOTHESIS_PROFILE=explore pytest ...`` draws fresh ones when hunting for new cases.
_hypothesis_settings.register_profile("ci", derandomize=True, print_blob=True)
_hypothesis_settings.register_profile("explore", derandomize=False, print_blob=True)
_hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
import pandas as pd
import pytest
from filelock import FileLock

from lumbar.experiments.l2s1 import scenario_grid as l2s1_scenario_grid
from lumbar.inputs.characteristics import load_characteristic_set

# parsed geometry files are cached by content across processes (lumbar.geometry.diskcache): one cache per test
# session, shared by its xdist workers and its Snakemake runs, never the user's own. The process that makes it (the
# xdist controller, or the single process) names it in _SESSION_CACHE_ENV for the workers it starts, and removes it
# at its exit; entries are written atomically, so processes may fill it at the same time.
_SESSION_CACHE_ENV = "LUMBAR_TEST_SESSION_CACHE"
if os.environ.get(_SESSION_CACHE_ENV) and os.environ.get("PYTEST_XDIST_WORKER"):
    _GEOMETRY_CACHE = os.environ[_SESSION_CACHE_ENV]
else:
    _GEOMETRY_CACHE = tempfile.mkdtemp(prefix="lumbar_test_cache_")
    os.environ[_SESSION_CACHE_ENV] = _GEOMETRY_CACHE
    atexit.register(shutil.rmtree, _GEOMETRY_CACHE, ignore_errors=True)
os.environ["LUMBAR_CACHE_DIR"] = _GEOMETRY_CACHE

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
VISIBLE_HUMAN = SHARED / "geometry" / "visible_human_lss"

# paper 1, Table 1 (Eq. 3 disc torque-angle fit: p1 [N*m], p2 [rad], p3 [N*m]); the calibrated set's disc.csv
# holds the same numbers (checked in test_characteristics.py), repeated here for the analytic tests.
TABLE1 = {"flexion": (10.67, 0.005913, -1.685), "extension": (5.196, 0.008417, 24.50),
          "lateral_bending": (6.929, 0.001482, 19.76), "axial_rotation": (4.399, 0.001141, 42.38)}

DAG_FIXTURES = {"dag_workdir", "dag_second_workdir", "dag_copy"}


# Tests in files this conftest's owner does not edit, measured over ~10 s each (or sharing a module fixture of
# ~30 s) on the 2-core CI machine: marked ``slow`` here so that the fast lane stays under 2 minutes. The default
# ``pytest`` still runs them. Owners: move the mark into the file (``@pytest.mark.slow``) and drop the entry.
SLOW_ELSEWHERE = {
    # the module fixtures ``baseline``/``standing`` solve the muscle model (~30 s); plus single heavy solves
    "test_muscle_model.py": {"fixtures": {"baseline", "standing"},
                             "names": {"test_cold_standing_solve_starts_near_reference_and_converges",
                                       "test_intra_abdominal_pressure_unloads_the_spine",
                                       "test_unreachable_posture_is_flagged_not_silent",
                                       "test_in_situ_standing_gives_in_situ_sarcomere_lengths_in_standing"}},
    # one `python -m lumbar.cli fsu` subprocess per case (2-15 s each)
    "test_fsu_cli.py": {"fixtures": set(),
                        "names": {"test_cli_exits_one_and_says_so_when_a_solve_does_not_converge"}},
}


# Session fixtures that are expensive and not shared between xdist workers: the tests that use one run on one worker
# (an xdist group of that name), so that it is built once.
SESSION_GROUPS = {"model": "muscle_model"}


def _xdist_group(item, stage: int) -> str | None:
    """The xdist group of a test (``--dist loadgroup``): the tests that share an expensive session fixture share its
    group; the tests of a module that use one of its module-scoped (or class-scoped) fixtures form one group per
    module (and per stage, see below), so that the fixture is built once; every other test is a unit of its own."""
    used = set(getattr(item, "fixturenames", ()))
    for name, group in SESSION_GROUPS.items():
        if name in used:
            return group
    defs = getattr(getattr(item, "_fixtureinfo", None), "name2fixturedefs", {})
    if any(fd.scope in ("module", "class") for name in used for fd in defs.get(name) or ()):
        return f"{item.path.stem}:{stage}"
    return None


@pytest.hookimpl(tryfirst=True)         # before xdist's own hook, which reads the groups
def pytest_collection_modifyitems(config, items):
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        if (DAG_FIXTURES | {"smk_tree"}) & fixtures:                  # runs Snakemake (smk_tree: test_bad_inputs)
            item.add_marker(pytest.mark.workflow)
        slow = SLOW_ELSEWHERE.get(item.path.name)
        if slow and (slow["fixtures"] & fixtures or item.originalname in slow["names"]):
            item.add_marker(pytest.mark.slow)
    # the tests that read the session's DAG runs last (same order among themselves), those that read the second run
    # after all others: they run beside the background Snakemake runs instead of the session waiting for them
    def stage(item):
        used = set(getattr(item, "fixturenames", ()))
        return 2 if "dag_second_workdir" in used else 1 if DAG_FIXTURES & used else 0
    items[:] = sorted(items, key=stage)
    if getattr(config.option, "loadgroup", False):            # an xdist worker with --dist loadgroup
        for item in items:
            group = _xdist_group(item, stage(item))
            if group and not item.get_closest_marker("xdist_group"):
                item.add_marker(pytest.mark.xdist_group(group))


def make_charset(name="calibrated", torque=None, ligaments=True, facet_stiffness=None, overrides=None,
                 **disc_fields):
    """The real :class:`lumbar.inputs.characteristics.CharacteristicSet` ``name`` (paper 1, Tables 1-3 for
    ``calibrated``) with ``overrides`` (dotted keys, see ``load_characteristic_set``). What the loader's
    overrides cannot express is replaced on the dataclasses: ``torque`` (Eq. 3 parameters per direction),
    ``ligaments=False`` (no ligaments at all), ``facet_stiffness`` (0 allowed: facets present, no force) and
    further disc fields (``k_shear=...``)."""
    cs = load_characteristic_set(name, overrides=overrides)
    disc = dataclasses.replace(cs.disc, **disc_fields, **({"torque": dict(torque)} if torque else {}))
    facet = cs.facet if facet_stiffness is None else dataclasses.replace(cs.facet, stiffness=float(facet_stiffness))
    return dataclasses.replace(cs, disc=disc, facet=facet, ligaments=dict(cs.ligaments) if ligaments else {})


@pytest.fixture
def charset():
    return make_charset()


def synthetic_l2s1_chain():
    """L2-S1 from the mirror-symmetric synthetic unit stacked four times (exactly symmetric in y)."""
    import copy

    import numpy as np

    from lumbar.geometry.core import SpineGeometry, Vertebra
    from lumbar.geometry.synthetic import BODY, DISC_HEIGHT, symmetric_fsu

    t = symmetric_fsu()
    lev = t.levels["L4-L5"]
    dz = DISC_HEIGHT + BODY[2]
    names = ["S1", "L5", "L4", "L3", "L2"]
    verts = {}
    for j, v in enumerate(names):
        m = t.vertebrae["L5"].mesh.copy()
        m.apply_translation([0, 0, j * dz])
        verts[v] = Vertebra(v, m, t.vertebrae["L5"].centroid + [0, 0, j * dz])
    levels = {}
    for i, lv in enumerate(["L5-S1", "L4-L5", "L3-L4", "L2-L3"]):
        L = copy.deepcopy(lev)
        s = np.array([0, 0, i * dz])
        L.name, (L.upper, L.lower) = lv, lv.split("-")
        L.disc_centre = lev.disc_centre + s
        for lig in L.ligaments:
            lig.upper, lig.lower = lig.upper + s, lig.lower + s
        for f in L.facets.values():
            f.superior, f.inferior = f.superior + s, f.inferior + s
        levels[lv] = L
    return SpineGeometry("synthetic_chain", "test", verts, levels)


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


# The session's DAG runs start in the background as soon as collection is finished (pytest_collection_finish),
# not when the first DAG test asks for them: the library tests then run beside the two Snakemake runs, which fill
# the cores the tests leave (the DAG has long serial chains), instead of leaving a core idle.
#
# Under pytest-xdist (``-n 2`` in pyproject.toml) every worker collects the same tests and needs the same runs: the
# first worker to finish its collection starts them (a file lock in the folder the workers share, the xdist docs'
# ``getbasetemp().parent`` pattern), each in a runner process of its own session that writes the run's exit code
# to a file when Snakemake ends; every worker waits for that file. No two Snakemake runs ever share a directory.
# The controller (or the single process without xdist) ends runs that are still going when the session ends.


# The second run (reproducibility) builds the model chain's tables and figures in a fresh copy: geometry, calibration,
# stepwise reduction, L2-S1, load sharing, admissibility and the muscle model's validation. It leaves out what has
# its own determinism test or whose tables the results-identity test pins to a reference run
# (tests/test_results_identity.py: every table but the muscle model's): the muscle sensitivity and Sobol chunks,
# the discrepancy stage, the other levels and the real-data validation tables, and the report (test_report.py).
# That keeps the second run to about half the first one's jobs beside it.
SECOND_RUN_TARGETS = [
    "results/tables/fsu_geometry.csv", "results/figures/fig1_l4l5_model.png", "results/tables/fsu_rom_intact.csv",
    "results/tables/table1_disc_calibrated.csv", "results/figures/fig4_disc_torque_angle.png",
    "results/figures/fig5_ligament_characteristics.png", "results/tables/table4_rom_synopsis.csv",
    "results/figures/fig6_rom_stepwise_reduction.png", "results/tables/table5_idp_synopsis.csv",
    "results/figures/fig7_idp.png", "results/load_sharing/load_sharing_summary.csv",
    "results/calibration/admissibility.csv", "results/tables/in_vivo_validation.csv",
]


# CPU priority (nice) of the background runs; their jobs inherit it. With two xdist workers the library tests fill
# both cores in small units whatever the order, while the first run has long serial chains (surrogate, calibration,
# posterior draws, bands) that many tests wait for: it runs at the tests' priority, so that it ends while the library
# tests still run. The second (read by one test, the last) takes what the others leave. The tests that read the runs
# come last (``pytest_collection_modifyitems``).
DAG_NICE = {"first": 0, "second": 5}


def is_xdist_worker(config) -> bool:
    return hasattr(config, "workerinput")


def shared_dir(config) -> Path:
    """A folder of this session that the xdist controller and all its workers see (the controller's base temporary
    folder; a worker's is a subfolder of it), or the single process's base temporary folder."""
    base = config._tmp_path_factory.getbasetemp()
    return base.parent if is_xdist_worker(config) else base


# A background job (the kernel warm-up, a Snakemake run): a process of its own session (so that the whole run, its
# jobs included, can be ended at once) that waits for a file to exist (the warm-up's end) if given, runs the command
# in its working directory with the output in ``out`` (first line: the wall time), then writes its exit code to
# ``rc`` (atomically: a reader never sees half of it). The first line of ``out`` gives the command's wall time and its
# CPU time (user + system of the command and every process it waited for: Snakemake's jobs).
_RUNNER = r"""
import os, resource, subprocess, sys, time
wait_for, out, rc_file, nice = sys.argv[1:5]
os.nice(int(nice))
t_end = time.time() + 1200
while wait_for and not os.path.exists(wait_for) and time.time() < t_end:
    time.sleep(0.3)
t0 = time.perf_counter()
with open(out + ".part", "w") as log:
    rc = subprocess.call(sys.argv[5:], stdout=log, stderr=subprocess.STDOUT)
text = open(out + ".part").read()
ru = resource.getrusage(resource.RUSAGE_CHILDREN)
with open(out, "w") as f:
    f.write(f"# {time.perf_counter() - t0:.1f} s wall, {ru.ru_utime + ru.ru_stime:.1f} s CPU\n" + text)
os.remove(out + ".part")
with open(rc_file + ".tmp", "w") as f:
    f.write(str(rc))
os.replace(rc_file + ".tmp", rc_file)
"""


_BACKGROUND = {}        # pid -> Popen of the background jobs this process started


def _start_background(cwd: Path, cmd, out: Path, rc: Path, nice=0, wait_for: Path | None = None) -> int:
    proc = subprocess.Popen([sys.executable, "-c", _RUNNER, str(wait_for or ""), str(out), str(rc), str(nice), *cmd],
                            cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    _BACKGROUND[proc.pid] = proc
    return proc.pid


def _alive(pid: int) -> bool:
    if pid in _BACKGROUND:                  # this process's child (a finished one is a zombie until polled)
        return _BACKGROUND[pid].poll() is None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def _end_background(pid: int):
    """End a background job's whole process group (the runner, Snakemake and its jobs)."""
    try:
        os.killpg(pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    for _ in range(120):
        if not _alive(pid):
            return
        time.sleep(0.5)
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


# The solver's numba kernels are compiled (or loaded from their on-disk cache) in a process of its own that starts
# with the session, so that the compilation (about 20 s on an empty cache, as on a fresh clone) runs beside the
# collection; the Snakemake runs wait for it, so that their jobs load the cache instead of each compiling at the same
# time. Started by the controller under xdist (the workers then share it) or by the single process.
WARM_UP = ["-c", "from lumbar.mechanics import kernel; kernel.warm_up()"]


def _warm_up_files(config):
    d = shared_dir(config)
    return d / "warm_up.out", d / "warm_up.rc"


def pytest_sessionstart(session):
    config = session.config
    if config.option.collectonly or is_xdist_worker(config):
        return
    out, rc = _warm_up_files(config)
    pid = _start_background(Path.cwd(), [sys.executable, *WARM_UP], out, rc)
    (shared_dir(config) / "warm_up.pid").write_text(str(pid))


def _dag_needed(items) -> set[str]:
    if not any(DAG_FIXTURES & set(getattr(i, "fixturenames", ())) for i in items):
        return set()
    return {"first"} | ({"second"} if any(i.name == "test_dag_reproducible_byte_identical" for i in items) else set())


def pytest_collection_finish(session):
    config = session.config
    if config.option.collectonly:
        return
    needed = _dag_needed(session.items)
    if not needed:
        return
    d = shared_dir(config)
    _, warm_rc = _warm_up_files(config)
    with FileLock(str(d / "dag_runs.lock")):
        for name in sorted(needed):
            info = d / f"dag_{name}.json"
            if info.exists():                 # another worker started it
                continue
            dest = copy_repo(d / f"dag_{name}" / "repo")
            targets = SECOND_RUN_TARGETS if name == "second" else []
            cmd = [sys.executable, "-m", "snakemake", *targets, "--cores", "2", "--configfile", TEST_CONFIG]
            pid = _start_background(dest, cmd, dest / "dag_run.out", d / f"dag_{name}.rc", DAG_NICE[name],
                                    wait_for=warm_rc)
            tmp = info.with_suffix(".tmp")
            tmp.write_text(json.dumps(dict(path=str(dest), pid=pid)))
            os.replace(tmp, info)


def pytest_sessionfinish(session, exitstatus):
    config = session.config
    if is_xdist_worker(config) or config.option.collectonly:
        return
    d = shared_dir(config)
    out, rc = _warm_up_files(config)
    pid_file = d / "warm_up.pid"
    if pid_file.exists():
        pid = int(pid_file.read_text())
        for _ in range(10):          # a short session (one test file) ends before the compilation: not waited for
            if rc.exists() or not _alive(pid):
                break
            time.sleep(0.5)
        if not rc.exists():
            _end_background(pid)
        elif rc.read_text().strip() != "0":  # the tests that use the kernel show the error; Snakemake jobs compile
            sys.stderr.write(f"conftest: kernel warm-up failed (exit {rc.read_text()}):\n"
                             f"{out.read_text()[-3000:] if out.exists() else ''}\n")
    for info in sorted(d.glob("dag_*.json")):     # e.g. -x stopped the session: leave no Snakemake run behind
        run = json.loads(info.read_text())
        if not (d / f"{info.stem}.rc").exists():
            _end_background(run["pid"])


def _wait_dag(config, name: str) -> Path:
    """Wait for the background run ``name``; fail the test with Snakemake's output and the logs if it failed."""
    d = shared_dir(config)
    run = json.loads((d / f"dag_{name}.json").read_text())
    path, rc_file = Path(run["path"]), d / f"dag_{name}.rc"
    t_end = time.time() + 1500
    while not rc_file.exists():
        if not _alive(run["pid"]) and not rc_file.exists():
            pytest.fail(f"the background Snakemake run {name} in {path} ended without an exit code", pytrace=False)
        if time.time() > t_end:
            pytest.fail(f"the background Snakemake run {name} in {path} did not end in 1500 s", pytrace=False)
        time.sleep(1.0)
    rc = int(rc_file.read_text())
    if rc != 0:
        _dag_failed(path, rc, (path / "dag_run.out").read_text())
    return path


def _dag_started(config, name: str) -> bool:
    return (shared_dir(config) / f"dag_{name}.json").exists()


@pytest.fixture(scope="session")
def dag_workdir(request, tmp_path_factory) -> Path:
    """Path of a copy of the repository in which ``snakemake --cores 2 --configfile config/test/config.yaml``
    (the whole default target ``all``) has run successfully. Read-only for tests: copy what you modify.
    Started in the background right after collection (see ``pytest_collection_finish``)."""
    if not _dag_started(request.config, "first"):     # not started at collection (should not happen): run it now
        work = copy_repo(tmp_path_factory.mktemp("dag") / "repo")
        run_dag(work)
        return work
    return _wait_dag(request.config, "first")


@pytest.fixture(scope="session")
def dag_second_workdir(request, dag_workdir, tmp_path_factory) -> Path:
    """A second, independent run of the model chain's targets (``SECOND_RUN_TARGETS``) in another fresh copy (for
    the reproducibility test), started at the same time as the first."""
    if not _dag_started(request.config, "second"):
        second = copy_repo(tmp_path_factory.mktemp("dag2") / "repo")
        run_dag(second, *SECOND_RUN_TARGETS)
        return second
    return _wait_dag(request.config, "second")


@pytest.fixture(scope="module")
def idp_model_fixture():
    """TEST FIXTURE in the schema of the nominal L2-S1 model table (rule discovery_idp_model): 49 scenarios with a
    disc force and sagittal moment pattern like the solved model's (not data)."""
    grid = l2s1_scenario_grid()
    rng = np.random.default_rng(3)
    F = 150 + 250 * rng.random(len(grid))
    M = np.array([{"flexion": 0.0, "extension": -5.0}.get(lc, -1.5) for _, lc in grid]) + rng.normal(0, 0.8, len(grid))
    per_n = 1.68 / 1.6e-3
    return pd.DataFrame({"muscle_setup": [g[0] for g in grid], "load_case": [g[1] for g in grid],
                         "converged": True, "idp_mpa": F * per_n / 1e6, "disc_axial_force_n": F,
                         "disc_moment_sagittal_nm": M, "idp_per_newton_pa": per_n})


@pytest.fixture(scope="session", name="model")
def muscle_model():
    """``model``: the default muscle-driven L1-S1 model (lumbar.muscles.muscle_model.LumbarMuscleModel), built once per
    session for test_muscles, test_muscle_model and test_nlp; read-only for tests (solvers take their settings
    from their own fixtures)."""
    from lumbar.muscles.muscle_model import LumbarMuscleModel
    return LumbarMuscleModel()

