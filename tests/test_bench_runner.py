"""benchmarks/run_all.py and benchmarks/bench_dag.py helpers (no benchmark is timed here)."""
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _load(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_parse_json_whole_or_last_object():
    run_all = _load("run_all")
    assert run_all.parse_json('{"a": 1}\n') == {"a": 1}
    assert run_all.parse_json('log line {not json}\n{"a": {"b": 2}}\n') == {"a": {"b": 2}}
    assert run_all.parse_json("no json here") is None


def test_dag_stage_sums_from_benchmark_files(tmp_path):
    bench_dag = _load("bench_dag")
    for name, s in (("calibrate", 12.5), ("stepwise_reduction_sim_rupp2015", 2.0),
                    ("stepwise_reduction_sim_calibrated", 3.0), ("l2s1_idp_rupp2015", 4.0), ("fsu_rom", 9.0)):
        (tmp_path / f"{name}.tsv").write_text(f"s\th:m:s\tmax_rss\n{s}\t0:00:01\t1.0\n")
    (tmp_path / "muscle_sobol_chunk").mkdir()             # rules that keep their files in a subfolder count too
    (tmp_path / "muscle_sobol_chunk" / "flexion_0.tsv").write_text("s\th:m:s\tmax_rss\n7.5\t0:00:07\t1.0\n")
    per_job = bench_dag.read_benchmarks(tmp_path)
    assert per_job["fsu_rom"] == 9.0 and per_job["muscle_sobol_chunk/flexion_0"] == 7.5
    assert bench_dag.stage_sums(per_job) == {"calibration": 12.5, "forward": 5.0, "idp": 4.0}


def test_run_all_skips_opensim_cleanly(tmp_path):
    """Without opensim in the given interpreter the OpenSim benchmark is recorded as skipped, exit 0."""
    fake = tmp_path / "nopython"
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "run_all.py"), "--only", "opensim",
                        "--opensim-python", str(fake), "--out-dir", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "out" / "opensim.json").read_text())
    assert res["skipped"] is True and "opensim" in res["reason"]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["opensim"]["result"]["skipped"] is True


def test_dag_baseline_tree_is_the_revision_and_a_bad_revision_is_named(tmp_path):
    """bench_dag --baseline: the baseline is the repository's tracked files at the revision (here HEAD, whose
    Snakefile is this checkout's committed one); a revision git does not know stops with its name before any run."""
    import pytest

    bench_dag = _load("bench_dag")
    if subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True).returncode != 0:
        pytest.skip("not a git checkout")
    tree = bench_dag.export_tree("HEAD", tmp_path / "baseline")
    committed = subprocess.run(["git", "-C", str(ROOT), "show", "HEAD:Snakefile"], capture_output=True,
                               text=True, check=True).stdout
    assert (tree / "Snakefile").read_text() == committed
    assert (tree / "src" / "lumbar" / "mechanics" / "kernel.py").is_file()
    # only tracked files: no outputs of a run, no caches
    assert [p.name for p in (tree / "results").iterdir()] == ["README.md"]
    assert not list(tree.rglob("__pycache__")) and not (tree / ".snakemake").exists()
    with pytest.raises(SystemExit, match="no-such-revision"):
        bench_dag.export_tree("no-such-revision", tmp_path / "bad")


def test_specimen_dag_credits_each_job_to_its_rule():
    """bench_specimen_dag: a benchmark file (rule, rule_<set>, rule/<chunk>) is credited to the longest rule name it
    starts with, so a rule whose name extends another's keeps its own time; control: with only the shorter name
    known, the longer rule's job falls to it."""
    bench = _load("bench_specimen_dag")
    per_job = {"calibrate": 2.0, "stepwise_reduction_sim_calibrated": 3.0, "stepwise_reduction_sim_rupp2015": 4.0,
               "stepwise_reduction_surrogate": 1.0, "muscle_sobol_chunk/flexion_0": 5.0, "specimen_geometry": 7.0}
    rules = {"calibrate", "stepwise_reduction_sim", "stepwise_reduction_surrogate", "muscle_sobol_chunk",
             "specimen_geometry"}
    assert bench.per_rule_seconds(per_job, rules) == {
        "calibrate": 2.0, "muscle_sobol_chunk": 5.0, "specimen_geometry": 7.0, "stepwise_reduction_sim": 7.0,
        "stepwise_reduction_surrogate": 1.0}
    fewer = bench.per_rule_seconds(per_job, {"stepwise_reduction"})
    assert fewer["stepwise_reduction"] == 8.0


def test_dag_profile_sums_jobs_per_rule(tmp_path):
    """bench_dag --profile: job files of one rule add up; shares of the jobs' wall time sum to 1; the time per
    equilibrium is the rule's solve time over its equilibria; a rule without equilibria has none."""
    bench_dag = _load("bench_dag")
    jobs = [("calibrate", 10.0, 6.0, 20000), ("calibrate", 30.0, 18.0, 40000), ("paper_report", 20.0, 0.0, 0)]
    for i, (rule, wall, solve, n) in enumerate(jobs):
        rec = {"rule": rule, "job": f"j{i}", "pid": i, "wall_s": wall, "cpu_s": wall * 0.9,
               "phases_s": {"startup_imports": 2.0, "fsu_solve": solve, "rest": wall - 2.0 - solve},
               "counts": {"equilibria": n, "muscle_postures": 0}}
        (tmp_path / f"{rule}__j{i}__{i}.json").write_text(json.dumps(rec))
    prof = bench_dag.read_profiles(tmp_path)
    cal, rep = prof["rules"]["calibrate"], prof["rules"]["paper_report"]
    assert list(prof["rules"]) == ["calibrate", "paper_report"]          # largest first
    assert cal["jobs"] == 2 and cal["wall_s"] == 40.0 and cal["counts"]["equilibria"] == 60000
    assert cal["fsu_solve_s_per_equilibrium"] == round(24.0 / 60000, 7)
    assert rep["fsu_solve_s_per_equilibrium"] is None
    assert abs(sum(r["share_of_jobs_wall"] for r in prof["rules"].values()) - 1.0) < 1e-3
    assert prof["phases_s"]["startup_imports"] == 6.0 and prof["jobs_wall_s"] == 60.0


def test_dag_finish_reports_the_cpu_of_the_whole_process_tree(tmp_path):
    """finish_dag's CPU time includes the children of the waited-for process (a job's CPU under Snakemake)."""
    bench_dag = _load("bench_dag")
    import time
    log = tmp_path / "log.txt"
    code = ("import subprocess, sys; subprocess.run([sys.executable, '-c', "
            "'import time\\nt=time.process_time()\\nwhile time.process_time()-t<0.6: pass'])")
    with log.open("w") as fh:
        proc = subprocess.Popen([sys.executable, "-c", code], stdout=fh, stderr=subprocess.STDOUT)
    rc, _, wall, usage = bench_dag.finish_dag(proc, time.perf_counter(), log, 120)
    assert rc == 0 and usage["cpu_s"] >= 0.6 and usage["max_rss_mb"] > 1
