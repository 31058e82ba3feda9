"""Run every benchmarks/bench_*.py, one after the other, and collect their JSON.

Writes ``results/benchmarks/<name>.json`` per benchmark (``<name>`` = script name without ``bench_``) and
``results/benchmarks/summary.json`` (every result, with the command, exit code and wall time of each run; a run
with ``--only`` or ``--skip`` updates the entries it ran and keeps the others).
``bench_opensim`` runs with the interpreter given by ``--opensim-python`` (or ``$LUMBAR_OPENSIM_PYTHON``; OpenSim is
an optional dependency in its own venv, see benchmarks/requirements-opensim.txt) and is skipped cleanly, with
``{"skipped": true, "reason": ...}``, when that interpreter cannot import ``opensim``. Usage::

    python benchmarks/run_all.py                                    # everything, DAG on config/config.yaml
    python benchmarks/run_all.py --opensim-python /path/to/osvenv/bin/python
    python benchmarks/run_all.py --dag-configfile config/test/config.yaml --skip opensim
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent


def parse_json(stdout: str):
    """The JSON object a benchmark printed (the whole output, or the last top-level object in it)."""
    text = stdout.strip()
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        pass
    dec = json.JSONDecoder()
    found = None
    i = text.find("{")
    while i != -1:
        try:
            obj, end = dec.raw_decode(text, i)
            found = obj
            i = text.find("{", end)
        except json.JSONDecodeError:
            i = text.find("{", i + 1)
    return found


def can_import(python: str, module: str) -> tuple[bool, str]:
    try:
        r = subprocess.run([python, "-c", f"import {module}"], capture_output=True, text=True, timeout=300)
    except (OSError, subprocess.TimeoutExpired) as e:
        return False, str(e)
    return r.returncode == 0, (r.stderr.strip().splitlines() or [""])[-1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out-dir", default=str(ROOT / "results" / "benchmarks"))
    ap.add_argument("--dag-configfile", default=None, help="--configfile for bench_dag (default: the paper's)")
    ap.add_argument("--opensim-python", default=os.environ.get("LUMBAR_OPENSIM_PYTHON", sys.executable))
    ap.add_argument("--skip", nargs="*", default=[], help="benchmark names to skip (e.g. dag opensim)")
    ap.add_argument("--only", nargs="*", default=None, help="run only these benchmark names")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per benchmark")
    a = ap.parse_args(argv)

    out_dir = Path(a.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary_path = out_dir / "summary.json"
    summary = {}
    if (a.only is not None or a.skip) and summary_path.is_file():   # a partial run updates the summary
        try:
            summary = json.loads(summary_path.read_text())
        except json.JSONDecodeError:
            summary = {}
    failed = 0
    for script in sorted(HERE.glob("bench_*.py")):
        name = script.stem.removeprefix("bench_")
        if name in a.skip or (a.only is not None and name not in a.only):
            continue
        python, args = sys.executable, []
        if name == "dag" and a.dag_configfile:
            args = ["--configfile", a.dag_configfile]
        if name == "opensim":
            python = a.opensim_python
            ok, why = can_import(python, "opensim")
            if not ok:
                res = {"skipped": True, "reason": f"opensim not importable by {python}: {why}",
                       "hint": "pass --opensim-python (see benchmarks/requirements-opensim.txt)"}
                summary[name] = {"result": res, "returncode": None, "command": None, "seconds": 0.0}
                (out_dir / f"{name}.json").write_text(json.dumps(res, indent=2, sort_keys=True) + "\n")
                print(f"[run_all] {name}: skipped ({res['reason']})", file=sys.stderr)
                continue
        cmd = [python, str(script)] + args
        print(f"[run_all] {name}: {' '.join(cmd)}", file=sys.stderr)
        t0 = time.perf_counter()
        try:
            r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=a.timeout)
            rc, stdout, stderr = r.returncode, r.stdout, r.stderr
        except subprocess.TimeoutExpired:
            rc, stdout, stderr = None, "", f"timeout after {a.timeout} s"
        dt = round(time.perf_counter() - t0, 2)
        res = parse_json(stdout)
        if res is None:
            res = {"error": "no JSON printed", "stderr_tail": stderr[-2000:]}
        if rc != 0:
            failed += 1
            res.setdefault("stderr_tail", stderr[-2000:])
        summary[name] = {"result": res, "returncode": rc, "command": cmd, "seconds": dt}
        (out_dir / f"{name}.json").write_text(json.dumps(res, indent=2, sort_keys=True) + "\n")
        print(f"[run_all] {name}: exit {rc} in {dt} s", file=sys.stderr)
    summary_path.write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    print(json.dumps({k: {"returncode": v["returncode"], "seconds": v["seconds"],
                          "skipped": bool(v["result"].get("skipped"))} for k, v in summary.items()}, indent=2))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
