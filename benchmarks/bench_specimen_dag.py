"""Benchmark: the DAG on a user's specimen against the default DAG, in one run (target: the specimen's no more than
20 % slower).

In a scratch copy of the repository (never the repository's own results/), one after the other and each with
``snakemake --cores 2`` on the same base configuration (default ``config/test/config.yaml``):

1. the **default** DAG (the base configuration's geometry, the embedded Visible Human set) into run ``default``
   (``results/default/``);
2. the **same DAG on a specimen given as meshes** into run ``specimen`` (``results/specimen/``). By default the
   specimen is the Visible Human set's L1-L5 and S1 meshes written as a user's STL folder in a CT-like pose
   (millimetres, LPS, turned by 35 deg and shifted to a table position: ``lumbar.geometry.specimen_accuracy.ct_pose``),
   so that both DAGs have the same units and stages and differ only by the specimen path (rule
   ``specimen_geometry``: alignment, atlas registration, discs, facets, QA figures; every other job loads the built
   geometry from the geometry cache). ``--specimen morphable_mean`` runs the embedded morphable lumbar mean
   (``config/test/morphable_mean.yaml``'s geometry; L2-L5, no sacrum: its DAG skips stages and is not the same DAG).

Both runs start cold (an empty numba cache and an empty geometry cache of their own, one BLAS thread per job), as
``bench_dag.py`` does. Prints one JSON object (and writes it to ``--out``): the wall seconds of both DAGs and their
ratio, their job counts per rule and what differs (rules only in one DAG, per-rule job wall-time sums from
Snakemake's benchmark files and the largest differences), the machine (cores, load average before and after each
run, a pure-Python speed reference before and after each run). On a shared machine the load changes between the
two runs; the JSON records it, and the jobs' summed wall times per rule say where a difference comes from.
Run by hand, not in CI (about 10-15 min with the test configuration). Usage::

    python benchmarks/bench_specimen_dag.py [--configfile config/test/config.yaml] [--specimen visible_human]
        [--out benchmarks/results/specimen_dag.json] [--keep] [--dry-run]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_dag import finish_dag, read_benchmarks, scratch_copy, speed_reference  # noqa: E402

TARGET_RATIO = 1.20            # the specimen's DAG no more than 20 % slower than the default DAG
SPECIMEN_POSE_SEED = 0         # ct_pose(seed): the CT-like pose of the Visible Human meshes


def write_visible_human_specimen(folder: Path) -> dict:
    """The Visible Human set's vertebra meshes as a user's STL folder (mm, LPS, CT-like pose); its geometry: config
    section."""
    from lumbar.geometry import load_geometry  # noqa: PLC0415 - only this specimen needs the library here
    from lumbar.geometry.specimen_accuracy import ct_pose, write_posed_meshes  # noqa: PLC0415
    write_posed_meshes(load_geometry("visible_human"), ct_pose(SPECIMEN_POSE_SEED), folder)
    return {"kind": "meshes", "path": str(folder), "units": "mm", "axes": "LPS"}


def run_config(work: Path, name: str, geometry: dict | None, extra: dict | None = None) -> str:
    """A config file in the copy naming the run (``run.name``) and, for a specimen, its geometry; returned relative
    to the copy."""
    cfg = {"run": {"name": name}}
    if geometry is not None:
        cfg["geometry"] = geometry
    cfg.update(extra or {})
    path = work / "config" / f"bench_{name}.yaml"
    path.write_text(json.dumps(cfg, indent=2))   # JSON is YAML
    return path.relative_to(work).as_posix()


def jobs_per_rule(work: Path, configfiles: list[str]) -> dict[str, int]:
    """Jobs per rule of the DAG (the job table of ``snakemake -n``)."""
    cmd = [sys.executable, "-m", "snakemake", "-n", "--cores", "2", "--configfile", *configfiles]
    r = subprocess.run(cmd, cwd=work, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(work / "src")))
    if r.returncode != 0:
        raise SystemExit(f"bench_specimen_dag: dry run failed ({' '.join(configfiles)}):\n{r.stdout[-3000:]}"
                         f"\n{r.stderr[-3000:]}")
    out = {}
    text = r.stdout + r.stderr
    table = re.search(r"Job stats:\s*\n\s*job\s+count\s*\n[-\s]+\n(.*?)\n\s*total\s+(\d+)", text, re.S)
    if table:
        for line in table.group(1).splitlines():
            parts = line.split()
            if len(parts) == 2 and parts[1].isdigit():
                out[parts[0]] = int(parts[1])
    return out


def rule_of(job: str) -> str:
    """The rule a benchmark file belongs to: ``rule`` or ``rule_<set>`` / ``rule/<chunk>`` (the rule names of the
    DAG's job table decide; see :func:`per_rule_seconds`)."""
    return job.split("/")[0]


def per_rule_seconds(per_job: dict[str, float], rules) -> dict[str, float]:
    """Summed job wall seconds per rule: each benchmark file is credited to the longest rule name it starts with."""
    names = sorted(rules, key=len, reverse=True)
    out = Counter()
    for job, s in per_job.items():
        stem = rule_of(job)
        rule = next((r for r in names if stem == r or stem.startswith(r + "_")), stem)
        out[rule] += s
    return {k: round(v, 3) for k, v in sorted(out.items())}


def timed_run(work: Path, tmp: Path, cores: int, configfiles: list[str], label: str, timeout: float) -> dict:
    load0 = os.getloadavg()[0]
    speed0 = speed_reference()
    proc, t0, log = _start(work, tmp, cores, configfiles, label)
    rc, text, wall, _ = finish_dag(proc, t0, log, timeout)
    steps = re.findall(r"(\d+) of (\d+) steps \(100%\) done", text or "")
    return dict(success=rc == 0, wall_time_s=round(wall, 2), jobs=int(steps[-1][1]) if steps else None,
                load_average_1min_before_after=[round(load0, 2), round(os.getloadavg()[0], 2)],
                speed_reference_s_before_after=[speed0, speed_reference()],
                **({} if rc == 0 else {"error_tail": (text or "")[-3000:]}))


def _start(work: Path, tmp: Path, cores: int, configfiles: list[str], label: str):
    """``bench_dag.start_dag`` with several config files (the base and the run's) and caches of the run's own."""
    cache = tmp / label
    cache.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "snakemake", "--cores", str(cores), "--configfile", *configfiles]
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1",
               NUMBA_CACHE_DIR=str(cache / "numba_cache"), LUMBAR_CACHE_DIR=str(cache / "geometry_cache"),
               PYTHONPATH=os.pathsep.join(p for p in (str(work / "src"), os.environ.get("PYTHONPATH")) if p))
    log = tmp / f"snakemake_{label}.log"
    with log.open("w") as fh:
        proc = subprocess.Popen(cmd, cwd=work, stdout=fh, stderr=subprocess.STDOUT, text=True, env=env)
    return proc, time.perf_counter(), log


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--configfile", default="config/test/config.yaml",
                    help="base configuration of both DAGs, relative to the repository")
    ap.add_argument("--specimen", choices=["visible_human", "morphable_mean"], default="visible_human")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--out", default=None, help="also write the JSON to this file")
    ap.add_argument("--keep", action="store_true", help="keep the scratch copy (its path is in the JSON)")
    ap.add_argument("--dry-run", action="store_true", help="only the two DAGs' job tables (snakemake -n), no timing")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds before a run is stopped")
    a = ap.parse_args(argv)

    tmp, work = scratch_copy("lumbar_bench_specimen_dag_")
    if a.specimen == "visible_human":
        geometry = write_visible_human_specimen(tmp / "specimen_meshes")
        extra = None
        specimen_note = (f"the Visible Human L1-L5 and S1 meshes written as STL files (mm, LPS, CT-like pose "
                         f"ct_pose({SPECIMEN_POSE_SEED}): 35 deg about a random axis, shifted to a table position)")
    else:
        geometry = {"kind": "meshes", "path": "data/geometry/morphable_lumbar_mean", "units": "mm",
                    "axes": "project"}
        extra = {"load_sharing": {"other_levels": ["L2-L3", "L3-L4"]}}
        specimen_note = "the embedded morphable lumbar mean (L2-L5, no sacrum: stages skipped, not the same DAG)"
    cfg_default = [a.configfile, run_config(work, "default", None)]
    cfg_specimen = [a.configfile, run_config(work, "specimen", geometry, extra)]
    rules_default = jobs_per_rule(work, cfg_default)
    rules_specimen = jobs_per_rule(work, cfg_specimen)
    out = {
        "benchmark": "specimen_dag",
        "configfile": a.configfile,
        "specimen": specimen_note,
        "cores": a.cores,
        "target_ratio": TARGET_RATIO,
        "jobs_per_rule": {"default": rules_default, "specimen": rules_specimen},
        "rules_only_in_specimen": sorted(set(rules_specimen) - set(rules_default)),
        "rules_only_in_default": sorted(set(rules_default) - set(rules_specimen)),
        "rules_with_other_job_counts": {r: [rules_default.get(r, 0), rules_specimen.get(r, 0)]
                                        for r in sorted(set(rules_default) | set(rules_specimen))
                                        if rules_default.get(r, 0) != rules_specimen.get(r, 0)},
    }
    if not a.dry_run:
        runs = {}
        for label, cfgs in (("default", cfg_default), ("specimen", cfg_specimen)):
            runs[label] = timed_run(work, tmp, a.cores, cfgs, label, a.timeout)
            per_job = read_benchmarks(work / "results" / label / "benchmarks")
            runs[label]["jobs_sum_s"] = round(sum(per_job.values()), 2)
            runs[label]["per_rule_s"] = per_rule_seconds(per_job, set(rules_default) | set(rules_specimen))
        out["runs"] = runs
        ok = runs["default"]["success"] and runs["specimen"]["success"]
        ratio = runs["specimen"]["wall_time_s"] / runs["default"]["wall_time_s"] if ok else None
        out["ratio_wall_time"] = round(ratio, 4) if ok else None
        out["ratio_jobs_sum"] = (round(runs["specimen"]["jobs_sum_s"] / runs["default"]["jobs_sum_s"], 4)
                                 if ok and runs["default"]["jobs_sum_s"] else None)
        out["within_target"] = bool(ok and ratio <= TARGET_RATIO)
        d, s = runs["default"]["per_rule_s"], runs["specimen"]["per_rule_s"]
        diff = {r: round(s.get(r, 0.0) - d.get(r, 0.0), 3) for r in set(d) | set(s)}
        out["largest_rule_differences_s"] = dict(sorted(diff.items(), key=lambda kv: -abs(kv[1]))[:12])
    out.update({
        "order": "default first, then specimen, one after the other in the same scratch copy (separate run "
                 "prefixes results/default, results/specimen)",
        "caches": "each run: an empty numba cache and an empty geometry cache of its own (compile and parse "
                  "times included)",
        "machine_note": "a shared machine (2 cores, other users' jobs running): the load average and the speed "
                        "reference before and after each run record its state; the two runs did not see the same "
                        "load",
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    })
    if a.keep:
        out["workdir"] = str(work)
    else:
        shutil.rmtree(tmp, ignore_errors=True)
    text = json.dumps(out, indent=2)
    print(text)
    if a.out:
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(text + "\n")
    ok = a.dry_run or (out["runs"]["default"]["success"] and out["runs"]["specimen"]["success"])
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
