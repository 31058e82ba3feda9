"""Shared fixtures: the real characteristic sets (``lumbar.inputs.characteristics``) with overrides, paths, and
``dag_workdir``: the whole default DAG run once per session on config/test in a copy of the repository.

Markers (pyproject.toml): every test that uses the session DAG (``dag_workdir``, ``dag_second_workdir`` or a
fixture built on them) is marked ``workflow`` here, so the fast lane ``pytest -m "not workflow and not slow"``
never starts Snakemake.
"""
import atexit
import dataclasses
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lumbar.experiments.l2s1 import scenario_grid as l2s1_scenario_grid
from lumbar.inputs.characteristics import load_characteristic_set

# parsed geometry files are cached by content across processes (lumbar.geometry.diskcache): one cache per test
# session, shared by its Snakemake runs, never the user's own
_GEOMETRY_CACHE = tempfile.mkdtemp(prefix="lumbar_test_cache_")
os.environ["LUMBAR_CACHE_DIR"] = _GEOMETRY_CACHE
atexit.register(shutil.rmtree, _GEOMETRY_CACHE, ignore_errors=True)

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
# not when the first DAG test asks for them: the library tests then run on the pytest process beside the two
# Snakemake runs, which fill both cores (the DAG has long serial chains), instead of leaving a core idle.
_DAG_RUNS = {}      # "first" / "second" -> dict(path, proc, log, t0, rc)


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


# CPU priority (nice) of the background runs; their jobs inherit it. The session's critical path is this pytest
# process, one test after another, then the tests that read the first run; the first run takes the CPU the tests
# leave, the second (read by one test, the last) what the first leaves. The tests that read the runs come last
# (``pytest_collection_modifyitems``).
DAG_NICE = {"first": 5, "second": 15}


def _start_dag(name: str, dest: Path, targets=()):
    copy_repo(dest)
    log = open(dest / "dag_run.out", "w")
    proc = subprocess.Popen([sys.executable, "-m", "snakemake", *targets, "--cores", "2", "--configfile",
                             TEST_CONFIG], cwd=dest, stdout=log, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=lambda: os.nice(DAG_NICE[name]))
    _DAG_RUNS[name] = dict(path=dest, proc=proc, log=log, t0=time.perf_counter(), rc=None)


# The solver's numba kernels are compiled (or loaded from their on-disk cache) in a process of their own that starts
# with the session, so that the compilation (about 20 s on an empty cache, as on a fresh clone) runs beside the
# collection; the Snakemake runs start once it is done, so that their jobs load the cache instead of each compiling
# at the same time.
_WARM_UP = {}


def pytest_sessionstart(session):
    if session.config.option.collectonly:
        return
    _WARM_UP["proc"] = subprocess.Popen(
        [sys.executable, "-c", "from lumbar.mechanics import kernel; kernel.warm_up()"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _wait_warm_up(timeout=None):
    proc = _WARM_UP.pop("proc", None)
    if proc is None:
        return
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:       # only at the session's end (see pytest_sessionfinish)
        proc.kill()
        proc.communicate()
        return
    if proc.returncode != 0:    # the tests that use the kernel will show the error; Snakemake jobs compile alone
        sys.stderr.write(f"conftest: kernel warm-up failed (exit {proc.returncode}):\n{err[-3000:]}\n")


def pytest_collection_finish(session):
    items = session.items
    if session.config.option.collectonly or not any(DAG_FIXTURES & set(getattr(i, "fixturenames", ()))
                                                    for i in items):
        return
    _wait_warm_up()
    factory = session.config._tmp_path_factory
    _start_dag("first", factory.mktemp("dag") / "repo")
    if any(i.name == "test_dag_reproducible_byte_identical" for i in items):
        _start_dag("second", factory.mktemp("dag2") / "repo", SECOND_RUN_TARGETS)


def pytest_sessionfinish(session, exitstatus):
    _wait_warm_up(timeout=5)      # a short session (one test file) ends before the compilation: not waited for
    for run in _DAG_RUNS.values():     # e.g. -x stopped the session: do not leave a Snakemake run behind
        if run["proc"].poll() is None:
            run["proc"].terminate()
            run["proc"].wait(timeout=60)
        if not run["log"].closed:
            run["log"].close()


def _wait_dag(name: str) -> Path:
    """Wait for the background run ``name``; fail the test with Snakemake's output and the logs if it failed."""
    run = _DAG_RUNS[name]
    if run["rc"] is None:
        run["rc"] = run["proc"].wait(timeout=1500)
        run["log"].close()
        out = (run["path"] / "dag_run.out").read_text()
        (run["path"] / "dag_run.out").write_text(f"# <= {time.perf_counter() - run['t0']:.1f} s\n" + out)
    if run["rc"] != 0:
        _dag_failed(run["path"], run["rc"], (run["path"] / "dag_run.out").read_text())
    return run["path"]


@pytest.fixture(scope="session")
def dag_workdir(tmp_path_factory) -> Path:
    """Path of a copy of the repository in which ``snakemake --cores 2 --configfile config/test/config.yaml``
    (the whole default target ``all``) has run successfully. Read-only for tests: copy what you modify.
    Started in the background right after collection (see ``pytest_collection_finish``)."""
    if "first" not in _DAG_RUNS:          # not started at collection (should not happen): run it now
        work = copy_repo(tmp_path_factory.mktemp("dag") / "repo")
        run_dag(work)
        return work
    return _wait_dag("first")


@pytest.fixture(scope="session")
def dag_second_workdir(dag_workdir, tmp_path_factory) -> Path:
    """A second, independent run of the model chain's targets (``SECOND_RUN_TARGETS``) in another fresh copy (for
    the reproducibility test), started at the same time as the first."""
    if "second" not in _DAG_RUNS:
        second = copy_repo(tmp_path_factory.mktemp("dag2") / "repo")
        run_dag(second, *SECOND_RUN_TARGETS)
        return second
    return _wait_dag("second")


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

