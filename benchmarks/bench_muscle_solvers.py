"""Benchmark: the two paths to a posture optimum side by side, one core.

For each activity (default: upright standing and 19 deg extension; ``--activities`` for more):
* ``sqp``: the hand-written SQP alone (``certifier: sqp``), cold from the reference pose;
* ``sqp+ipopt``: the workflow's path, the SQP's optimum certified by IPOPT (its convergence test at that point,
  IPOPT iterations only where it fails);
* ``ipopt``: IPOPT alone (CasADi, lumbar.muscles.nlp), cold from the SQP's start pose (the thorax rotation spread
  over the levels, zero activations), with its Hessian from differences of the exact gradients,
  ``--ipopt-max-iter`` iterations at most.
Prints one JSON object with time, L4-L5 IDP, cost, equilibrium residual, tracking error, IPOPT's NLP error and status per
path, and the ratios (ipopt / sqp time and cost). Usage: python benchmarks/bench_muscle_solvers.py
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from lumbar.muscles import muscle_model as mm  # noqa: E402


def _idp(model, x, R):
    seg = model.segment_loads(x[None], R[None]).query("level == 'L4-L5'").iloc[0]
    return round(float(mm.idp_parts([seg["compressive_n"]], [seg["moment_nm"]])[0][0]), 4)


def _row(t, cost, resid, terr, kkt, status, reached, certified, it, idp):
    return {"time_s": round(t, 3), "l4l5_idp_mpa": idp, "cost": float(f"{cost:.8g}"), "equilibrium_residual": float(f"{resid:.2e}"),
            "tracking_error_deg": round(float(terr), 4), "ipopt_nlp_error": float(f"{kkt:.2e}"), "status": status,
            "reached": bool(reached), "certified": bool(certified), "iterations": int(it)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--activities", nargs="+", default=["upright_standing", "extension_19deg"])
    ap.add_argument("--ipopt-max-iter", type=int, default=150)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    model = mm.LumbarMuscleModel()
    sqp = mm.make_solver(model, {"certifier": "sqp"})
    cert = mm.make_solver(model)
    out = {"benchmark": "muscle_solvers", "ipopt_max_iter": args.ipopt_max_iter, "activities": {}}
    for act in args.activities:
        A = mm.get_activity(act)
        F, P = model.load_arrays([A])
        params = {"force_vec": F, "force_pt": P}
        res = {}
        t = time.perf_counter()
        s = mm.solve_postures(model, sqp, [act])[0]
        t_sqp = time.perf_counter() - t
        chk = cert.certifier.certify(A.thorax_flexion_deg, params, s.x, s.R, s.a)
        res["sqp"] = _row(t_sqp, s.cost, max(s.residual_force_n, s.residual_moment_nm), s.tracking_error_deg,
                          chk.kkt_residual, chk.status, s.reached, s.certified, s.iterations, _idp(model, s.x, s.R))
        t = time.perf_counter()
        c = mm.solve_postures(model, cert, [act])[0]
        res["sqp+ipopt"] = _row(time.perf_counter() - t, c.cost, max(c.residual_force_n, c.residual_moment_nm),
                                c.tracking_error_deg, c.kkt_residual, c.ipopt_status, c.reached, c.certified,
                                c.iterations, _idp(model, c.x, c.R))
        x0, R0 = cert.initial_pose(A.thorax_flexion_deg)
        t = time.perf_counter()
        r = cert.certifier.solve(A.thorax_flexion_deg, params, x0, R0, np.zeros(model.ms.n), warm=False,
                                 max_iter=args.ipopt_max_iter)
        t_ip = time.perf_counter() - t
        st = cert.evaluate_state(r.x[None], r.R[None], r.a[None], params, [A.thorax_flexion_deg])
        terr = float(np.linalg.norm(st["e"][0]))
        res["ipopt"] = _row(t_ip, float(st["c"][0]), r.equilibrium_residual, terr, r.kkt_residual, r.status,
                            r.equilibrium_residual < 1e-6 and terr <= cert.max_tracking_deg, r.success, r.iterations,
                            _idp(model, r.x, r.R))
        res["ratio_ipopt_to_sqp_time"] = round(t_ip / t_sqp, 1)
        res["ratio_ipopt_to_sqp_cost"] = round(res["ipopt"]["cost"] / s.cost, 5)
        out["activities"][act] = res
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
