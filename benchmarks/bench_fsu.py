"""Benchmark: L4-L5 equilibria per second on the workflow's default unit, the compiled solver core beside the numpy
reference path (and a per-scenario scipy baseline), measured in the same run on one core.

The headline row is what the workflow solves: the configuration's geometry (config/config.yaml ``geometry``; the
Visible Human set) with the calibrated characteristic set of the DAG (``results/calibration/characteristics``
through ``lumbar.inputs.characteristics.resolve_characteristic_set``; without a calibration output the published
set, with a printed note), intact unit with its facet joints (how many contact points and joints carry load is
reported at rest and at the equilibria). Scenarios: pure moments 0.5-10 N*m in the four main directions from the
0 N*m equilibrium. Both paths solve the same scenarios; their equilibria are compared (max difference). Extra rows:
the published set on the same geometry and the published set on myo-sim (the previous headline). The cold start of
the compiled core (a fresh interpreter: compiling with an empty numba cache, and loading from the cache) is timed in
subprocesses. Rates are given per wall second and per CPU second of this process (``*_per_cpu_second``: the
one-core figure when other jobs share the machine; the load average is recorded before and after).

The same-run comparison with an earlier commit (``--baseline-commit``, default 80ee759, the solver core before its
last speed-up): the commit's tree is extracted (``git archive``) into a temporary folder (or ``--baseline-tree``),
and the default unit's compiled rate is measured in fresh interpreters on that tree's ``src`` and on this tree's,
alternately (``--rounds`` each; the best of each counts: the machine's load only ever slows a run), by this script's
``--rate-only`` mode, the same scenarios and the same geometry and characteristic set for both; the ratio of the two
and the largest difference of their equilibria are recorded (``vs_baseline``). The JSON is printed and written to
``benchmarks/results/fsu_equilibria.json`` (``--out``). Usage::

    python benchmarks/bench_fsu.py [--n 2000] [--n-reference 1000] [--n-baseline 20] [--no-cold-start]
                                   [--baseline-commit 80ee759 | --baseline-tree DIR | --no-baseline-commit]
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import root  # noqa: E402

import lumbar  # noqa: E402

from lumbar.experiments.fsu import MAIN_DIRECTIONS, build_fsu, moment_loads  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set, resolve_characteristic_set  # noqa: E402
from lumbar.inputs.config import load_config  # noqa: E402
from lumbar.mechanics import kernel, so3  # noqa: E402
from lumbar.mechanics.elements.facet import contact_penalty  # noqa: E402
from lumbar.mechanics.solve import solve  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TARGET_EQUILIBRIA_PER_S = 30_000
TARGET_SPEEDUP = 5.0
#: the commit the compiled core is compared with in the same run, and the speed-up it must show (equilibria per CPU
#: second of the default unit, best of the rounds of each)
BASELINE_COMMIT = "80ee759"
TARGET_SPEEDUP_VS_BASELINE = 2.5


def scenarios(n, seed=0):
    rng = np.random.default_rng(seed)
    dirs = [MAIN_DIRECTIONS[i % 4] for i in range(n)]
    return dirs, rng.uniform(0.5, 10.0, n)


def baseline_one(m, x0, R0, load):
    def fun(q):
        x = x0 + q[:3][None, None]
        R = so3.exp(q[3:][None, None]) @ R0
        Q, _ = m.evaluate_reference(x, R, load[None], jacobian=False)
        return Q[0, 0]
    sol = root(fun, np.zeros(6), method="hybr", options={"xtol": 1e-12})
    return sol.success and np.abs(fun(sol.x)[:3]).max() < 1e-6 and np.abs(fun(sol.x)[3:]).max() < 1e-6


def facets_in_contact(m, x, R):
    """Contact points carrying load per state (B,) and joints (surfaces) carrying load per state (B,)."""
    p, _ = m._attach(x, R, m.k_a, m.k_s)
    P = m._to_body(x, R, m.k_b, p)
    g = np.empty(P.shape[:-1])
    for sid, surf in enumerate(m.surfaces):
        sel = m.k_surf == sid
        g[:, sel] = surf.gap(P[:, sel])[0]
    F, _ = contact_penalty(-g, m.k_stiff, m.contact_eps)
    return (F > 0).sum(1), (m.contact_forces(x, R) > 0).sum(1)


def best_time(fn, repeat):
    """Best wall time, best CPU time of this process (the one-core figure on a shared, loaded machine), result."""
    best, best_cpu, out = np.inf, np.inf, None
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        best, best_cpu = min(best, time.perf_counter() - t), min(best_cpu, time.process_time() - c)
    return best, best_cpu, out


def case(geo, cs, n, n_ref, repeat, label, set_origin):
    """Equilibria per second of the compiled core and of the reference path on the same scenarios."""
    fsu = build_fsu(geo, cs)
    m = fsu.model
    r0 = solve(m, np.zeros((1, m.nb, 6)))
    dirs, M = scenarios(n)
    loads = moment_loads(dirs, M, m.nb)
    x0, R0 = np.repeat(r0.x, n, 0), np.repeat(r0.R, n, 0)
    with kernel.use("compiled"):
        solve(m, loads[:4], x0=x0[:4], R0=R0[:4])                  # compiled (or loaded from the cache) here
        tc, cc, rc = best_time(lambda: solve(m, loads, x0=x0, R0=R0), repeat)
    with kernel.use("reference"):
        tr, cr, rr = best_time(lambda: solve(m, loads[:n_ref], x0=x0[:n_ref], R0=R0[:n_ref]), max(1, repeat - 1))
    k = min(n, n_ref)
    pts_rest, joints_rest = facets_in_contact(m, r0.x, r0.R)
    pts, joints = facets_in_contact(m, rc.x, rc.R)
    eps_c, eps_r = int(rc.converged.sum()) / tc, int(rr.converged.sum()) / tr
    cpu_c, cpu_r = int(rc.converged.sum()) / cc, int(rr.converged.sum()) / cr
    return m, r0, loads, {
        "case": label, "geometry": geo.name, "characteristic_set": cs.name, "set_from": set_origin,
        "stage": "intact", "n_fibres": m.nf, "n_contact_points": m.nc, "n_facet_joints": len(m.surfaces),
        "facet_points_in_contact_at_rest": int(pts_rest[0]), "facet_joints_in_contact_at_rest": int(joints_rest[0]),
        "facet_points_in_contact_at_equilibria_mean": round(float(pts.mean()), 2),
        "scenarios_with_facet_contact": int((joints > 0).sum()),
        "n_scenarios": n, "converged": int(rc.converged.sum()), "newton_iterations_mean": round(
            float(rc.iterations.mean()), 3),
        "compiled_seconds": round(tc, 4), "equilibria_per_second": round(eps_c, 1),
        "reference_scenarios": n_ref, "reference_converged": int(rr.converged.sum()),
        "reference_seconds": round(tr, 4), "reference_equilibria_per_second": round(eps_r, 1),
        "speedup_vs_reference": round(eps_c / eps_r, 2),
        "equilibria_per_cpu_second": round(cpu_c, 1), "reference_equilibria_per_cpu_second": round(cpu_r, 1),
        "speedup_vs_reference_cpu": round(cpu_c / cpu_r, 2),
        "same_iterations_as_reference": bool((rc.iterations[:k] == rr.iterations[:k]).all()),
        "max_abs_diff_x_m": float(f"{np.abs(rc.x[:k] - rr.x[:k]).max():.3g}"),
        "max_abs_diff_rotation_rad": float(f"{np.abs(so3.log(rc.R[:k] @ np.swapaxes(rr.R[:k], -1, -2))).max():.3g}"),
    }


def evaluation_cost(m, r0, loads, repeat):
    """Microseconds per scenario of one residual evaluation, with and without the Jacobian, on both paths (what a
    reuse of the factorised Jacobian across Newton iterations could save at most)."""
    n = loads.shape[0]
    x, R = np.repeat(r0.x, n, 0), np.repeat(r0.R, n, 0)
    out = {}
    for mode in kernel.MODES:
        with kernel.use(mode):
            for jac in (True, False):
                _, t, _ = best_time(lambda: m.evaluate(x, R, loads, jacobian=jac), repeat)
                out[f"{mode}_cpu_us{'_with' if jac else '_without'}_jacobian"] = round(t / n * 1e6, 3)
    return out


def cold_start():
    """Seconds of import + first L4-L5 solve in a fresh interpreter: numba compiling (empty cache) and loading."""
    code = ("import time; t = time.perf_counter(); import numpy as np; from lumbar.mechanics.solve import solve; "
            "from lumbar.geometry.synthetic import symmetric_fsu; from lumbar.experiments.fsu import build_fsu; "
            "from lumbar.inputs.characteristics import load_characteristic_set as L; "
            "m = build_fsu(symmetric_fsu(), L('calibrated')).model; t1 = time.perf_counter(); "
            "solve(m, np.zeros((2, 1, 6))); m.evaluate(*m.reference_state(1)); "
            "print(t1 - t, time.perf_counter() - t1)")
    out = {}
    with tempfile.TemporaryDirectory() as d:
        for name, cache in (("empty_cache", d), ("cached", d)):
            env = {**os.environ, "NUMBA_CACHE_DIR": cache, "LUMBAR_KERNEL": "compiled"}
            r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=900)
            if r.returncode:
                return {"error": r.stderr.strip().splitlines()[-1:]}
            imp, first = (float(v) for v in r.stdout.split())
            out[f"first_solve_s_{name}"] = round(first, 3)
            out[f"import_and_build_s_{name}"] = round(imp, 3)
    r = subprocess.run([sys.executable, "-c", code], env={**os.environ, "LUMBAR_KERNEL": "reference"},
                       capture_output=True, text=True, timeout=900)          # the reference path, for comparison
    if r.returncode == 0:
        out["first_solve_s_reference_path"] = round(float(r.stdout.split()[1]), 3)
    return out


def rate_only(calibrated_dir, n, repeat, save=None):
    """The default unit's compiled rate in this interpreter (whichever ``lumbar`` it imports): best wall and CPU time
    of ``repeat`` solves of the ``n`` benchmark scenarios from the 0 N*m equilibrium. Uses only what 80ee759 has
    (build_fsu, solve, kernel.use, moment_loads), so that the same code measures both trees."""
    geo, cs, origin = default_unit(calibrated_dir)
    m = build_fsu(geo, cs).model
    r0 = solve(m, np.zeros((1, m.nb, 6)))
    dirs, M = scenarios(n)
    loads = moment_loads(dirs, M, m.nb)
    x0, R0 = np.repeat(r0.x, n, 0), np.repeat(r0.R, n, 0)
    with kernel.use("compiled"):
        solve(m, loads[:4], x0=x0[:4], R0=R0[:4])
        t, c, r = best_time(lambda: solve(m, loads, x0=x0, R0=R0), repeat)
    if save:
        np.savez(save, x=r.x, R=r.R, iterations=r.iterations, converged=r.converged)
    ok = int(r.converged.sum())
    return {"lumbar": str(Path(lumbar.__file__).resolve().parents[1]), "set_from": origin, "n_scenarios": n,
            "converged": ok, "newton_iterations_mean": round(float(r.iterations.mean()), 3),
            "seconds": round(t, 4), "cpu_seconds": round(c, 4), "equilibria_per_second": round(ok / t, 1),
            "equilibria_per_cpu_second": round(ok / c, 1)}


def baseline_tree(commit, dest):
    """Extract ``commit`` of this repository into ``dest`` (git archive); returns dest."""
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    arch = subprocess.run(["git", "-C", str(ROOT), "archive", commit], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=arch, check=True)
    return dest


def vs_baseline(tree, label, calibrated_dir, n, repeat, rounds):
    """Same-run comparison of this tree's compiled rate with ``tree``'s (fresh interpreters, alternately)."""
    runs = {"baseline": [], "current": []}
    src = {"baseline": Path(tree) / "src", "current": ROOT / "src"}
    with tempfile.TemporaryDirectory() as d:
        for k in range(rounds):
            for name in ("baseline", "current"):
                env = {**os.environ, "PYTHONPATH": str(src[name]), "LUMBAR_KERNEL": "compiled",
                       "NUMBA_CACHE_DIR": str(Path(d) / f"numba_{name}")}
                cmd = [sys.executable, str(Path(__file__).resolve()), "--rate-only", "--calibrated-dir",
                       str(calibrated_dir), "--n", str(n), "--repeat", str(repeat), "--save",
                       str(Path(d) / f"{name}.npz")]
                r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=3600)
                if r.returncode:
                    return {"error": f"{name}: " + " ".join(r.stderr.strip().splitlines()[-2:])}
                runs[name].append(json.loads(r.stdout.strip().splitlines()[-1]))
        eq = {name: np.load(Path(d) / f"{name}.npz") for name in runs}
        diff_x = float(np.abs(eq["current"]["x"] - eq["baseline"]["x"]).max())
        diff_r = float(np.abs(so3.log(eq["current"]["R"] @ np.swapaxes(eq["baseline"]["R"], -1, -2))).max())
        same_it = bool((eq["current"]["iterations"] == eq["baseline"]["iterations"]).all())
    best = {name: {key: max(v[key] for v in runs[name]) for key in ("equilibria_per_second",
                                                                        "equilibria_per_cpu_second")}
            for name in runs}
    for name in runs:
        assert Path(runs[name][0]["lumbar"]) == src[name].resolve(), (name, runs[name][0]["lumbar"])
    speed = best["current"]["equilibria_per_cpu_second"] / best["baseline"]["equilibria_per_cpu_second"]
    return {
        "baseline": label, "rounds": rounds, "n_scenarios": n, "repeat": repeat,
        "baseline_equilibria_per_second": best["baseline"]["equilibria_per_second"],
        "baseline_equilibria_per_cpu_second": best["baseline"]["equilibria_per_cpu_second"],
        "current_equilibria_per_second": best["current"]["equilibria_per_second"],
        "current_equilibria_per_cpu_second": best["current"]["equilibria_per_cpu_second"],
        "speedup_cpu": round(speed, 2),
        "speedup_wall": round(best["current"]["equilibria_per_second"] / best["baseline"]["equilibria_per_second"],
                              2),
        "target_speedup": TARGET_SPEEDUP_VS_BASELINE, "meets_target": bool(speed >= TARGET_SPEEDUP_VS_BASELINE),
        "same_iterations": same_it, "max_abs_diff_x_m": float(f"{diff_x:.3g}"),
        "max_abs_diff_rotation_rad": float(f"{diff_r:.3g}"),
        "runs": runs,
    }


def default_unit(calibrated_dir):
    """(geometry, characteristic set, origin note) of the workflow's default configuration. In ``--rate-only`` runs
    on an earlier tree (``vs_baseline``) that tree's ``lumbar`` may not know this tree's newer configuration keys: the
    four keys read here (geometry kind and path, the unit's level, the characteristics folder) come from the file as
    written there, unvalidated."""
    try:
        cfg = load_config(ROOT / "config" / "config.yaml")
    except Exception:  # noqa: BLE001 - an earlier lumbar's validator; the keys below are plain
        import yaml  # noqa: PLC0415

        cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    g = cfg["geometry"]
    path = ROOT / g["path"] if g["kind"] == "visible_human" else None
    geo = load_geometry(g["kind"], path=path, levels=[cfg["fsu"]["level"]])
    data_dir = ROOT / cfg["characteristics"]["data_dir"]
    cs = resolve_characteristic_set("calibrated", data_dir=data_dir, calibrated_dir=calibrated_dir)
    if (Path(calibrated_dir) / "disc.csv").is_file():
        return geo, cs, str(calibrated_dir)
    print(f"note: no calibration output in {calibrated_dir} (run the workflow's calibrate rule first): the "
          "calibrated set falls back to the published set as printed (data/characteristics)", file=sys.stderr)
    return geo, cs, "data/characteristics (published; no calibration output)"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=2000, help="scenarios of the compiled runs")
    p.add_argument("--n-reference", type=int, default=1000, help="scenarios of the reference runs")
    p.add_argument("--n-baseline", type=int, default=20, help="scenarios of the scipy baseline")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--calibrated-dir", default=str(ROOT / "results" / "calibration" / "characteristics"))
    p.add_argument("--no-cold-start", action="store_true", help="skip the fresh-interpreter timings")
    p.add_argument("--no-extra", action="store_true", help="only the default unit")
    p.add_argument("--baseline-commit", default=BASELINE_COMMIT, help="commit compared with in the same run")
    p.add_argument("--baseline-tree", default=None, help="an extracted tree of the baseline (instead of git archive)")
    p.add_argument("--no-baseline-commit", action="store_true", help="skip the same-run comparison with a commit")
    p.add_argument("--rounds", type=int, default=3, help="alternating fresh-interpreter runs per tree")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "fsu_equilibria.json"))
    p.add_argument("--rate-only", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--save", default=None, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.rate_only:                       # one fresh-interpreter measurement (of whichever tree is on PYTHONPATH)
        out = rate_only(a.calibrated_dir, a.n, a.repeat, a.save)
        print(json.dumps(out))
        return out
    if not kernel.active():
        print("note: the compiled core is not active (numba missing or LUMBAR_KERNEL=reference)", file=sys.stderr)
    geo, cs, origin = default_unit(a.calibrated_dir)
    m, r0, loads, head = case(geo, cs, a.n, a.n_reference, a.repeat, "default unit", origin)
    nb_ = min(a.n_baseline, a.n)
    t = time.perf_counter()
    ok = [baseline_one(m, r0.x, r0.R, loads[i]) for i in range(nb_)]
    tb = time.perf_counter() - t
    eps_base = sum(ok) / tb if sum(ok) else float("nan")
    out = {
        "benchmark": "fsu_equilibria", "kernel": kernel.mode() if kernel.active() else "reference (numba missing)",
        **head,
        "target_equilibria_per_second": TARGET_EQUILIBRIA_PER_S, "target_speedup_vs_reference": TARGET_SPEEDUP,
        "meets_target_wall": bool(head["equilibria_per_second"] >= TARGET_EQUILIBRIA_PER_S
                                  and head["speedup_vs_reference"] >= TARGET_SPEEDUP),
        "meets_target_cpu": bool(head["equilibria_per_cpu_second"] >= TARGET_EQUILIBRIA_PER_S
                                 and head["speedup_vs_reference_cpu"] >= TARGET_SPEEDUP),
        "baseline": "scipy.optimize.root(method='hybr', finite-difference Jacobian) per scenario, reference residual",
        "baseline_scenarios": nb_, "baseline_converged": int(sum(ok)), "baseline_seconds": round(tb, 4),
        "baseline_equilibria_per_second": round(eps_base, 1),
        "speedup_vs_scipy_root": round(head["equilibria_per_second"] / eps_base, 1) if eps_base == eps_base else None,
        "evaluation_cost": evaluation_cost(m, r0, loads[:500], max(3, a.repeat)),
        "load_average_1_5_15_min": [round(v, 2) for v in os.getloadavg()], "cpu_count": os.cpu_count(),
    }
    if not a.no_extra:
        pub = load_characteristic_set("calibrated")
        out["extra"] = [
            case(geo, pub, a.n, a.n_reference, a.repeat, "published set, default geometry",
                 "data/characteristics (published)")[3],
            case(load_geometry("myo_sim", levels=["L4-L5"]), pub, a.n, a.n_reference, a.repeat,
                 "published set, myo-sim geometry", "data/characteristics (published)")[3],
        ]
    if not a.no_cold_start:
        out["cold_start"] = cold_start()
    if not a.no_baseline_commit:
        with tempfile.TemporaryDirectory() as d:
            tree = a.baseline_tree or baseline_tree(a.baseline_commit, Path(d) / "tree")
            label = a.baseline_tree or a.baseline_commit
            out["vs_baseline"] = vs_baseline(tree, label, a.calibrated_dir, a.n, a.repeat, a.rounds)
    out["load_average_1_5_15_min_end"] = [round(v, 2) for v in os.getloadavg()]
    text = json.dumps(out, indent=2)
    print(text)
    if a.out:
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(text + "\n")
    return out


if __name__ == "__main__":
    main()
