"""Benchmark: cold wall time of the whole Snakemake DAG (target ``all``) on 2 cores, in a fresh copy of the repository.

Prints one JSON object: the wall time and its ratio to the 300 s target, the per-job times Snakemake measured
(``benchmark:`` files, ``results/benchmarks/*.tsv`` of the copy), and the sum of the calibration, forward
(stepwise reduction, one job per set) and IDP (L2-S1, one job per set) stages against the 60 s target.
The copy leaves the repository's own results/ untouched; ``../shared`` is linked beside the copy so that config
paths relative to the repository (``../shared/...``) resolve as they do in the repository. Usage::

    python benchmarks/bench_dag.py                                   # config/config.yaml (the paper's)
    python benchmarks/bench_dag.py --configfile config/test/config.yaml --cores 2 [--keep]
    python benchmarks/bench_dag.py --baseline HEAD~3      # this tree and HEAD~3 at the same time, one core each
    python benchmarks/bench_dag.py --baseline 80ee759 --profile benchmarks/results/dag_profile.json

``--profile OUT`` also writes where the time goes (OUT, JSON): every job of this tree runs with ``LUMBAR_PROFILE_DIR``
set (:mod:`lumbar.mechanics.profile`: start-up and imports, the compiled core's compile or cache load, geometry
parsing, equilibrium solves, muscle-posture solves and the rest, with the number of equilibria solved), summed per
rule with each rule's share of the jobs' time and its time per equilibrium; the whole command's wall, CPU (user +
system, every process of the run: ``wait4`` on Snakemake) and peak RSS of its largest process, beside the baseline's
and the compiled core's rate measured in the same run (``bench_fsu.py --rate-only`` on each tree, before the DAGs).

On a shared machine whose speed changes (the project's virtual machine: severalfold within an hour) two runs made
one after the other do not compare; ``--baseline`` runs both versions at the same time and gives their ratios.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IGNORE = shutil.ignore_patterns(".git", "results", ".snakemake", "logs", ".venv", "__pycache__", "*.egg-info",
                                ".pytest_cache", ".hypothesis")
TARGET_S = 300.0          # the cold default DAG on 2 idle cores: under 5 minutes
STAGES_TARGET_S = 60.0
# stage -> regular expression of the benchmark file names (= rule name, plus _<set> for per-set jobs)
STAGES = {"calibration": r"calibrate", "forward": r"stepwise_reduction_sim_.+", "idp": r"l2s1_idp_.+"}


def scratch_copy(prefix: str) -> tuple[Path, Path]:
    """A scratch copy of the repository (no results, logs, caches or git) with ../shared linked beside it, as a clean
    checkout sits: (its temporary folder, the copy)."""
    tmp = Path(tempfile.mkdtemp(prefix=prefix))
    work = tmp / ROOT.name
    shutil.copytree(ROOT, work, ignore=IGNORE, symlinks=True)
    shared = ROOT.parent / "shared"
    if shared.is_dir():
        (tmp / "shared").symlink_to(shared, target_is_directory=True)
    return tmp, work


def read_benchmarks(bench_dir: Path) -> dict[str, float]:
    """Wall seconds of every job from Snakemake's benchmark TSV files (first row, column ``s``), including those of
    rules that keep theirs in a subfolder (``muscle_sobol_chunk/flexion_0.tsv`` -> ``muscle_sobol_chunk/flexion_0``)."""
    out = {}
    for p in sorted(bench_dir.rglob("*.tsv")):
        with p.open() as f:
            rows = list(csv.DictReader(f, delimiter="\t"))
        if rows and "s" in rows[0]:
            out[p.relative_to(bench_dir).with_suffix("").as_posix()] = round(float(rows[0]["s"]), 3)
    return out


def stage_sums(per_job: dict[str, float]) -> dict[str, float]:
    return {stage: round(sum(t for name, t in per_job.items() if re.fullmatch(rx, name)), 3)
            for stage, rx in STAGES.items()}


def speed_reference(n=2_000_000, repeats=3) -> float:
    """Seconds of a fixed pure-Python loop (best of ``repeats``): the machine's single-core speed at the moment.
    Measured before and after the DAG, it records the state of a shared (throttled) machine. It does not normalise a
    run: on the project's virtual machine it did not track the numpy/numba jobs closely; compare two versions by
    running both DAGs at the same time (``--cores 1`` each)."""
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        acc = 0
        for i in range(n):
            acc += i * i
        best = min(best, time.perf_counter() - t)
    return round(best, 4)


def export_tree(rev: str, dest: Path) -> Path:
    """The repository's tracked files at ``rev`` (a commit, tag or branch) in ``dest`` (``git archive``): the
    baseline of a same-run comparison."""
    dest.mkdir(parents=True, exist_ok=True)
    arch = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", rev], capture_output=True, check=False)
    if arch.returncode != 0:
        raise SystemExit(f"bench_dag: --baseline {rev!r} is not a revision of {ROOT}: "
                         f"{arch.stderr.decode(errors='replace').strip()}")
    subprocess.run(["tar", "-x", "-C", str(dest)], input=arch.stdout, check=True)
    return dest


def start_dag(tree: Path, tmp: Path, cores: int, configfile):
    """Start ``snakemake --cores cores`` in ``tree`` with its own library (``tree/src`` first on the path), an empty
    numba cache and an empty geometry cache of its own and one thread per BLAS; returns (process, start time, its log
    file in ``tmp``)."""
    cmd = [sys.executable, "-m", "snakemake", "--cores", str(cores)]
    if configfile:
        cmd += ["--configfile", configfile]
    # cold also for the compiled kernels: an empty numba cache, as in a fresh clone (the installed package may be an
    # editable install whose cache is warm), so their compile time is part of the wall time; likewise the parsed
    # geometry files (lumbar.geometry.diskcache): the DAG's first reader of a mesh parses it
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               NUMBA_CACHE_DIR=str(tmp / f"numba_cache_{tree.name}"),
               LUMBAR_CACHE_DIR=str(tmp / f"geometry_cache_{tree.name}"),
               PYTHONPATH=os.pathsep.join(p for p in (str(tree / "src"), os.environ.get("PYTHONPATH")) if p),
               LUMBAR_PROFILE_DIR=str(tmp / f"profile_{tree.name}"))
    # the output to files, not pipes: of two runs at once, the one not being read would stall on a full pipe
    log = tmp / f"snakemake_{tree.name}.log"
    with log.open("w") as fh:
        proc = subprocess.Popen(cmd, cwd=tree, stdout=fh, stderr=subprocess.STDOUT, text=True, env=env)
    return proc, time.perf_counter(), log


def finish_dag(proc, t0, log, timeout):
    """(exit code or None on timeout, Snakemake's output, wall seconds, resource use) of a run from
    :func:`start_dag`. The resource use is ``wait4``'s of the Snakemake process: user and system CPU seconds of it and
    every job it waited for, and the peak RSS of the largest of them (MB)."""
    note, usage = "", None
    while True:
        pid, status, ru = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            usage = {"cpu_user_s": round(ru.ru_utime, 2), "cpu_system_s": round(ru.ru_stime, 2),
                     "cpu_s": round(ru.ru_utime + ru.ru_stime, 2), "max_rss_mb": round(ru.ru_maxrss / 1024, 1)}
            break
        if time.perf_counter() - t0 > timeout:
            proc.kill()
            proc.wait()
            note = f"timeout after {timeout} s\n"
            break
        time.sleep(0.5)
    wall = time.perf_counter() - t0
    return proc.returncode if usage else None, note + log.read_text(errors="replace"), wall, usage


def read_profiles(folder: Path) -> dict:
    """The job profiles of a run (:mod:`lumbar.mechanics.profile` files) summed per rule: jobs, wall and CPU seconds,
    phases, counts, each rule's share of the jobs' wall time and its seconds per equilibrium (solve time and whole
    job time), largest rules first."""
    rules: dict[str, dict] = {}
    for p in sorted(folder.glob("*.json")):
        rec = json.loads(p.read_text())
        r = rules.setdefault(rec["rule"], {"jobs": 0, "wall_s": 0.0, "cpu_s": 0.0, "phases_s": {}, "counts": {}})
        r["jobs"] += 1
        r["wall_s"] += rec["wall_s"]
        r["cpu_s"] += rec["cpu_s"]
        for k, v in rec["phases_s"].items():
            r["phases_s"][k] = r["phases_s"].get(k, 0.0) + v
        for k, v in rec["counts"].items():
            r["counts"][k] = r["counts"].get(k, 0) + v
    total = sum(r["wall_s"] for r in rules.values()) or 1.0
    for r in rules.values():
        n = r["counts"].get("equilibria", 0)
        r["share_of_jobs_wall"] = round(r["wall_s"] / total, 4)
        r["fsu_solve_s_per_equilibrium"] = round(r["phases_s"].get("fsu_solve", 0.0) / n, 7) if n else None
        r["job_s_per_equilibrium"] = round(r["wall_s"] / n, 7) if n else None
        m = r["counts"].get("muscle_postures", 0)
        r["muscle_solve_s_per_posture"] = round(r["phases_s"].get("muscle_solve", 0.0) / m, 4) if m else None
        r["wall_s"], r["cpu_s"] = round(r["wall_s"], 2), round(r["cpu_s"], 2)
        r["phases_s"] = {k: round(v, 2) for k, v in r["phases_s"].items()}
    phases: dict[str, float] = {}
    counts: dict[str, int] = {}
    for r in rules.values():
        for k, v in r["phases_s"].items():
            phases[k] = round(phases.get(k, 0.0) + v, 2)
        for k, v in r["counts"].items():
            counts[k] = counts.get(k, 0) + v
    ordered = dict(sorted(rules.items(), key=lambda kv: -kv[1]["wall_s"]))
    return {"jobs": sum(r["jobs"] for r in rules.values()), "jobs_wall_s": round(total, 2),
            "jobs_cpu_s": round(sum(r["cpu_s"] for r in rules.values()), 2),
            "phases_s": phases, "phase_shares": {k: round(v / total, 4) for k, v in phases.items()},
            "counts": counts, "rules": ordered}


def kernel_rate(tree: Path, tmp: Path) -> dict | None:
    """The compiled core's equilibria per second on ``tree``'s library (``bench_fsu.py --rate-only`` of this
    repository, in a fresh interpreter with ``tree/src`` first on the path; best of 3), or None if it failed."""
    save = tmp / f"rate_{tree.name}.npz"
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
               NUMBA_CACHE_DIR=str(tmp / f"numba_rate_{tree.name}"),
               PYTHONPATH=os.pathsep.join(p for p in (str(tree / "src"), os.environ.get("PYTHONPATH")) if p))
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_fsu.py"), "--rate-only", "--save", str(save)],
                       cwd=tree, env=env, capture_output=True, text=True, check=False)
    if r.returncode != 0:
        return None
    try:
        return json.loads(r.stdout[r.stdout.index("{"):])
    except ValueError:
        return None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--configfile", default=None, help="config file, relative to the repository (default: the "
                    "Snakefile's config/config.yaml)")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--baseline", default=None, metavar="REV",
                    help="also run the DAG of git revision REV at the same time, each run on half of --cores, and "
                         "report the ratios (a comparison that a shared machine's changing speed does not bias; "
                         "the wall time is then not the target's)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary copy (its path is in the JSON)")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds before the run is stopped")
    ap.add_argument("--profile", default=None, metavar="OUT",
                    help="also write where the time goes (per rule and phase, equilibrium counts, the whole "
                         "command's wall, CPU and RSS beside the baseline's and the kernel rate) to OUT (JSON)")
    a = ap.parse_args(argv)

    tmp, work = scratch_copy("lumbar_bench_dag_")
    cores = max(1, a.cores // 2) if a.baseline else a.cores
    base = export_tree(a.baseline, tmp / "baseline") if a.baseline else None
    rates = {}
    if a.profile:     # the compiled core's rate on each tree, in the same run (before the DAGs, one at a time)
        rates = {"this_tree": kernel_rate(work, tmp)}
        if base is not None:
            rates["baseline"] = kernel_rate(base, tmp)
    load_before = os.getloadavg()
    speed_before = speed_reference()
    runs = [start_dag(work, tmp, cores, a.configfile)]
    if base is not None:
        runs.append(start_dag(base, tmp, cores, a.configfile))
    (rc, err, wall, usage), *rest = [finish_dag(p, t0, log, a.timeout) for p, t0, log in runs]
    speed_after = speed_reference()
    per_job = read_benchmarks(work / "results" / "benchmarks")
    stages = stage_sums(per_job)
    n_jobs = re.findall(r"(\d+) of (\d+) steps \(100%\) done", err or "")
    out = {
        "benchmark": "dag_cold",
        "configfile": a.configfile or "config/config.yaml (Snakefile default)",
        "cores": cores,
        "success": rc == 0,
        "jobs": int(n_jobs[-1][1]) if n_jobs else None,
        "wall_time_s": round(wall, 2),
        "resources": usage,
        "target_s": TARGET_S,
        "ratio_to_target": round(wall / TARGET_S, 4),
        "stages_s": stages,
        "stages_sum_s": round(sum(stages.values()), 3),
        "stages_target_s": STAGES_TARGET_S,
        "stages_ratio_to_target": round(sum(stages.values()) / STAGES_TARGET_S, 4),
        "stages_note": "sum of the job wall times of rules calibrate, stepwise_reduction_sim (every set) and "
                       "l2s1_idp (every set), from their benchmark files; jobs may overlap in time on 2 cores",
        "per_job_s": per_job,
        "jobs_sum_s": round(sum(per_job.values()), 2),
        # the share of the cores' time the benchmarked jobs filled (the few jobs without a benchmark file are left
        # out, so this is a lower bound): near 1, the wall time is set by the work, not by the schedule
        "core_utilisation": round(sum(per_job.values()) / (cores * wall), 3) if wall > 0 else None,
        # the machine's speed before and after (speed_reference: lower is faster): a record of its state
        "speed_reference_s_before_after": [speed_before, speed_after],
        "numba_cache": "empty at the start (compile time included)",
        "geometry_cache": "empty at the start (the first reader of each geometry file parses it)",
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        # other processes on the machine inflate every time: the 1-minute load average before and after the run
        "load_average_1min_before_after": [round(load_before[0], 2), round(os.getloadavg()[0], 2)],
    }
    if base is not None:
        b_rc, b_err, b_wall, b_usage = rest[0]
        b_jobs = read_benchmarks(base / "results" / "benchmarks")
        ok = rc == 0 and b_rc == 0
        out["baseline"] = {"revision": a.baseline, "success": b_rc == 0, "wall_time_s": round(b_wall, 2),
                           "resources": b_usage, "jobs_sum_s": round(sum(b_jobs.values()), 2),
                           "stages_s": stage_sums(b_jobs), "per_job_s": b_jobs}
        cpu_ratio = (round(usage["cpu_s"] / b_usage["cpu_s"], 4) if ok and usage and b_usage and b_usage["cpu_s"]
                     else None)
        out["ratio_to_baseline"] = {
            "wall_time": round(wall / b_wall, 4) if ok else None,
            "cpu_time": cpu_ratio,
            "jobs_sum": round(sum(per_job.values()) / sum(b_jobs.values()), 4) if ok and b_jobs else None}
        out["baseline_note"] = (f"both DAGs ran at the same time on {cores} core(s) each: the ratios compare the two "
                                "versions on the same machine state; the wall time is not the target's (2 cores, one "
                                "DAG), so ratio_to_target is not given")
        out.update(ratio_to_target=None, stages_ratio_to_target=None)
        if b_rc != 0:
            out["baseline"]["error_tail"] = (b_err or "")[-2000:]
    if rc != 0:   # a failed run has no meaningful time: no ratios
        out.update(ratio_to_target=None, stages_ratio_to_target=None, error_tail=(err or "")[-2000:])
    if a.profile:
        prof = read_profiles(tmp / f"profile_{work.name}")
        doc = {"benchmark": "dag_profile", "configfile": out["configfile"], "cores_per_run": cores,
               "success": out["success"], "command": {"wall_s": out["wall_time_s"], **(usage or {})},
               "kernel_rate": rates.get("this_tree"), "profile": prof}
        if base is not None:
            doc["baseline"] = {"revision": a.baseline, "command": {"wall_s": out["baseline"]["wall_time_s"],
                                                                  **(out["baseline"]["resources"] or {})},
                               "kernel_rate": rates.get("baseline"), "jobs_sum_s": out["baseline"]["jobs_sum_s"]}
            kr = [rates.get("this_tree"), rates.get("baseline")]
            doc["ratio_to_baseline"] = dict(out["ratio_to_baseline"], kernel_rate=(
                round(kr[0]["equilibria_per_second"] / kr[1]["equilibria_per_second"], 4) if all(kr) else None))
            doc["note"] = out["baseline_note"]
        doc["load_average_1min_before_after"] = out["load_average_1min_before_after"]
        Path(a.profile).parent.mkdir(parents=True, exist_ok=True)
        Path(a.profile).write_text(json.dumps(doc, indent=2) + "\n")
    if a.keep:
        out["workdir"] = str(work)
    else:
        shutil.rmtree(tmp, ignore_errors=True)
    print(json.dumps(out, indent=2))
    return 0 if rc == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
