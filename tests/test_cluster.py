"""The cluster route without a cluster: a slice of the test configuration's DAG (two cheap jobs) run through the
generic cluster executor (snakemake-executor-plugin-cluster-generic, pinned in requirements-test.txt) with the
workflow profile workflow/profiles/cluster_generic, whose submit script starts every job as a process of its own
(as sbatch does with workflow/profiles/slurm; docs/workflow.md, "Running on a cluster"). Each job runs its own
Snakemake on its job script and reads only its declared inputs; the tables it writes equal the reference run's
(tests/data/results_test_config.tar.gz, compared as tests/test_results_identity.py does)."""
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import TEST_CONFIG, copy_repo
from test_results_identity import fit_dependent, numeric_differences, rm

PROFILE = "workflow/profiles/cluster_generic"
#: two jobs of the test configuration that no fit touches (so their tables are compared strictly), ~10 s of work
TARGETS = ("results/tables/fsu_geometry.csv", "results/stepwise_reduction/rom_rupp2015.csv")

pytestmark = pytest.mark.workflow


@pytest.fixture(scope="module")
def plugin():
    if importlib.util.find_spec("snakemake_executor_plugin_cluster_generic") is None:
        pytest.skip("snakemake-executor-plugin-cluster-generic is not installed (pip install -r requirements-test.txt)")


def _snakemake(work: Path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakemake", "--workflow-profile", PROFILE, *args,
                           "--configfile", TEST_CONFIG], cwd=work, capture_output=True, text=True, timeout=600)


def test_jobs_run_as_processes_of_their_own_through_the_cluster_executor(plugin, tmp_path):
    work = copy_repo(tmp_path / "repo")
    r = _snakemake(work, *TARGETS)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out[-6000:]
    # every job was submitted by the profile's submit script, once, as a process of its own
    submitted = [line.split("\t") for line in (work / "logs" / "cluster" / "submitted.tsv").read_text().splitlines()]
    assert len(submitted) == len(TARGETS), submitted
    assert len({pid for pid, _ in submitted}) == len(TARGETS)
    assert sorted(script.split(".")[1] for _, script in submitted) == ["fsu_geometry", "stepwise_reduction_sim"]
    for pid, script in submitted:
        assert f"with external jobid '{pid}'" in out, out[-6000:]
        job_log = (work / "logs" / "cluster" / f"{script}.log").read_text()
        assert "1 of 1 steps (100%) done" in job_log, job_log[-3000:]      # the job's own Snakemake ran it
    # what the jobs wrote is the reference run's result
    snap = rm.read_snapshot()
    results = work / "results"
    for target in TARGETS:
        rel = str(Path(target).relative_to("results"))
        assert not fit_dependent(rel)
        assert numeric_differences(snap[rel], (results / rel).read_bytes()) == [], rel


def test_a_submission_that_fails_fails_the_run(plugin, tmp_path):
    """The control: a submit command that fails (a scheduler that refuses the job) is an error of the run."""
    work = copy_repo(tmp_path / "repo")
    r = _snakemake(work, "--cluster-generic-submit-cmd", "false", TARGETS[0])
    assert r.returncode != 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert not (work / TARGETS[0]).exists()
