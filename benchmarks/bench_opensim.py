"""Benchmark: the L4-L5 unit in OpenSim 4.6 beside lumbar's batched Newton solver.

Prints one JSON object (and writes it to ``--out`` when given). Both engines model exactly the same
elements of reduction stage ``wo_va`` (default; no facet joints, so contact is not part of the
comparison): the disc (Eq. 3 torque-angle per project axis with flexion/extension split by sign,
axial compression ``k2 c^2 + k1 c`` without tension, linear shear) and the ALL and PLL fibres
(softplus Eq. 7 in percent strain with prestrain, tension-only with lumbar's C1 slack ramp, the
ligament force shared by its fibres). ``--stage intact_no_facets`` adds the posterior ligaments
(intact unit with facet stiffness 0).

OpenSim model: ground = the project frame (x anterior, y left, z superior; gravity off), L5 welded to
ground, L4 on a FreeJoint whose frames sit at the disc centre. Disc = two
``ExpressionBasedBushingForce`` between L5 and L4 frames at the disc centre:

* rotation bushing (frames parallel to the project axes). With ``--disc-mapping exact`` (default)
  its Mx/My/Mz expressions compute lumbar's rotation vector ``phi = log(R_FM)`` from the bushing's
  body-fixed X-Y-Z angles, apply Eq. 3 to it and map the resulting torque ``T`` (a spatial torque in
  the lower body's frame, as lumbar applies it) to the generalised forces conjugate to the angles,
  ``M = (R_FM H)^T T`` with ``H = N^-1`` (OpenSim applies ``R_GM ~N M`` to frame2), so both engines
  have identical constitutive laws. ``--disc-mapping naive`` uses ``M_i = T_i(theta_i)`` (what a
  modeller would write by hand); it differs at second order in the coupled rotations.
* translation bushing (frames aligned with lumbar's disc frame: e3 = disc normal): Fx, Fy linear
  shear, Fz compression only - identical to lumbar's disc-frame translational law.

Ligament fibres = ``ExpressionBasedPointToPointForce`` per fibre (expression in ``d`` and ``ddot``).
Pure moment = ``PrescribedForce`` torque on L4 in the ground frame. OpenSim has no static solver for
this, so each equilibrium is reached by forward dynamics from the 0 N*m rest state until all speeds
fall below ``--speed-tol``; L4's mass and inertia (0.1 kg, 1e-4 kg m^2) and the damping only shape
the transient, not the equilibrium. ROM = rotation vector of L4 relative to the rest state (project
axes), component about the loading axis - the same quantity ``lumbar.experiments.fsu.range_of_motion`` reports.

Usage (OpenSim lives in its own venv, see benchmarks/requirements-opensim.txt)::

    /work/osvenv/bin/python benchmarks/bench_opensim.py [--out results/benchmarks/opensim_side_by_side.json]

If ``opensim`` cannot be imported the script prints ``{"skipped": true, ...}`` and exits 0.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from lumbar.experiments import export_opensim  # noqa: E402
from lumbar.mechanics import kernel, so3  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.mechanics.elements.ligament import slack_length  # noqa: E402
from lumbar.experiments.fsu import (DIRECTIONS, MAIN_DIRECTIONS, build_fsu, disc_frame, moment_loads,  # noqa: E402
                        range_of_motion, removed_structures)
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.mechanics.solve import solve  # noqa: E402

MOMENTS_NM = (2.5, 10.0)
# comparison cases: name -> (lumbar stage, what OpenSim models)
CASES = {
    "wo_va": ("wo_va", "disc + ALL + PLL (stage w/o VA: no facets, no posterior ligaments)"),
    "intact_no_facets": ("intact", "disc + all ligaments (intact stage built with facet stiffness 0)"),
}
L4_MASS_KG = 0.1
L4_INERTIA_KGM2 = 1e-4
TARGET_SPEEDUP_LARGE_BATCH = 1000.0
TARGET_SPEEDUP_SINGLE = 50.0
# what of lumbar's L4-L5 unit OpenSim 4.6 can express, and so what this benchmark compares
STRUCTURES = {
    "disc": "compared: two ExpressionBasedBushingForce (Eq. 3 torque on lumbar's rotation vector; compression-only "
            "axial law and linear shear in the disc frame)",
    "ligaments": "compared: one ExpressionBasedPointToPointForce per fibre (softplus Eq. 7 with prestrain, "
                 "tension-only with the C1 slack ramp, force shared by the fibres)",
    "facet_joints": "not compared: OpenSim has no equivalent of the facet regression-surface contact (contact points "
                    "of the upper vertebra against the cubic surface of paper 1 Eq. 4 carried by the lower vertebra, "
                    "smoothed linear penalty along the surface normal); its contact forces act between spheres, "
                    "half-spaces and meshes (Hunt-Crossley, elastic foundation), not a fitted polynomial surface. "
                    "The compared stages have no facets (wo_va) or facet stiffness 0 (intact_no_facets)",
}


def import_opensim():
    """(module, None) or (None, reason)."""
    try:
        import opensim  # noqa: PLC0415 - optional engine; its absence is reported, not fatal
    except Exception as e:  # noqa: BLE001 - ImportError, or a broken binary wheel
        return None, f"opensim not importable: {type(e).__name__}: {e}"
    opensim.Logger.setLevelString("warn")   # the Manager logs every integrate() call at "info"
    opensim.Logger.removeFileSink()         # no opensim.log in the working directory
    return opensim, None


def load_case(level="L4-L5"):
    geo = load_geometry("default", levels=[level])
    cs = load_characteristic_set("calibrated")
    return geo, cs


def scenario_grid(moments=MOMENTS_NM, directions=MAIN_DIRECTIONS):
    return [(d, float(M)) for d in directions for M in moments]


# ------------------------------------------------------------------ lumbar side
def lumbar_side(geo, cs, case="wo_va", moments=MOMENTS_NM, directions=MAIN_DIRECTIONS, repeat=5,
                level="L4-L5", n_large=1000):
    """ROM (deg) per scenario and wall time per equilibrium, batched and one scenario at a time."""
    stage = CASES[case][0]
    fsu = build_fsu(geo, cs, level, facet_stiffness_n_per_m=0.0)
    grid = scenario_grid(moments, directions)
    n = len(grid)
    best_batch = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        df = range_of_motion(fsu, moments, directions, stages=[stage])
        best_batch = min(best_batch, time.perf_counter() - t)
    # one at a time: rest state once, then one Newton solve (batch of 1) per scenario
    m = fsu.model
    fm, cm = fsu.masks([stage])
    r0 = solve(m, np.zeros((1, m.nb, 6)), fmask=fm, cmask=cm)
    loads = moment_loads([g[0] for g in grid], [g[1] for g in grid], m.nb)
    best_single = np.inf
    rom_single = np.empty(n)
    for _ in range(repeat):
        t = time.perf_counter()
        for i, (d, _M) in enumerate(grid):
            r = solve(m, loads[i:i + 1], x0=r0.x, R0=r0.R, fmask=fm, cmask=cm)
            ax, sg = DIRECTIONS[d]
            rom_single[i] = np.degrees(so3.log(r.R[0, 0] @ r0.R[0, 0].T)[ax] * sg) if r.converged[0] else np.nan
        best_single = min(best_single, time.perf_counter() - t)
    t = time.perf_counter()
    for _ in range(repeat):
        solve(m, np.zeros((1, m.nb, 6)), fmask=fm, cmask=cm)
    t_rest = (time.perf_counter() - t) / repeat
    assert np.allclose(rom_single, df["rom_deg"].to_numpy(), atol=1e-6, equal_nan=True)
    # large batch: the same scenarios tiled to n_large (throughput of one batched Newton solve)
    idx = np.arange(n_large) % n
    best_large = np.inf
    for _ in range(max(1, repeat // 2)):
        t = time.perf_counter()
        rl = solve(m, loads[idx], x0=np.repeat(r0.x, n_large, 0), R0=np.repeat(r0.R, n_large, 0),
                   fmask=fm, cmask=cm)
        best_large = min(best_large, time.perf_counter() - t)
    return {
        "time_large_batch_s": best_large / n_large, "n_large": n_large,
        "large_batch_converged": int(rl.converged.sum()),
        "fsu": fsu, "table": df, "rom_deg": df["rom_deg"].to_numpy(),
        "converged": df["converged"].to_numpy(),
        "time_batch_s": best_batch / n,        # includes the batched 0 N*m rest solve
        "time_single_s": best_single / n + t_rest / n,
        "time_single_solve_only_s": best_single / n,
        "time_rest_s": t_rest,
    }


# ------------------------------------------------------------------ OpenSim side
def disc_moment_expressions(torque, mapping="exact"):
    """(Mx, My, Mz) Lepton expressions of the disc's rotational stiffness in theta_x/y/z.

    ``exact``: the export's mapping (:func:`lumbar.experiments.export_opensim.disc_moment_expressions`: Eq. 3 on
    lumbar's rotation vector computed from the bushing's angles, the torque mapped to the angles' generalised
    forces). ``naive``: M_i = T_i(theta_i), what a modeller would write by hand.
    """
    if mapping == "exact":
        return export_opensim.disc_moment_expressions(torque)
    if mapping != "naive":
        raise ValueError(f"disc mapping must be 'exact' or 'naive', got {mapping!r}")
    lb, fl, ex, ar = (torque[k] for k in ("lateral_bending", "flexion", "extension", "axial_rotation"))
    eq3 = export_opensim.eq3_expression
    return (eq3("theta_x", lb), f"step(theta_y)*{eq3('theta_y', fl)}+(1-step(theta_y))*{eq3('theta_y', ex)}",
            eq3("theta_z", ar))


def disc_force_expressions(k_quadratic, k_linear, k_shear, k_tension=0.0):
    """(Fx, Fy, Fz) in the disc frame: OpenSim applies ``-F`` to frame2 (restoring); the export's."""
    return export_opensim.disc_force_expressions(k_quadratic, k_linear, k_shear, k_tension)


def fibre_expression(law, l0, extra, scale, slack_width_pct, damping):
    """Tension [N] of one softplus fibre as a Lepton text (the export's, :func:`lumbar.experiments.export_opensim.
    fibre_expression`)."""
    return export_opensim.fibre_expression(law.a, law.b, law.c, law.d, l0, extra, scale, slack_width_pct, damping)


class OpenSimFSU:
    """The L4-L5 unit as an OpenSim model, ready for repeated pure-moment equilibria."""

    def __init__(self, osim, geo, cs, case="wo_va", level="L4-L5", disc_mapping="exact",
                 rot_damping=0.05, trans_damping=300.0, fibre_damping=5.0, slack_width_pct=0.5,
                 integrator="RungeKuttaMerson", accuracy=1e-7, max_step_s=2e-3):
        self.osim = osim
        lev = geo.levels[level]
        self.level = lev
        stage = CASES[case][0]
        gone = removed_structures(stage)
        c4 = np.asarray(geo.vertebrae[lev.upper].centroid, float)
        c5 = np.asarray(geo.vertebrae[lev.lower].centroid, float)
        centre = np.asarray(lev.disc_centre, float)
        V = osim.Vec3
        v3 = lambda a: V(*map(float, a))  # noqa: E731
        model = osim.Model()
        model.setName(f"lumbar_{level}_{case}")
        model.setGravity(V(0, 0, 0))
        L5 = osim.Body(lev.lower, 1.0, V(0), osim.Inertia(1e-3, 1e-3, 1e-3))
        L4 = osim.Body(lev.upper, L4_MASS_KG, V(0), osim.Inertia(L4_INERTIA_KGM2, L4_INERTIA_KGM2, L4_INERTIA_KGM2))
        model.addBody(L5)
        model.addBody(L4)
        model.addJoint(osim.WeldJoint("weld_" + lev.lower, model.getGround(), v3(c5), V(0), L5, V(0), V(0)))
        model.addJoint(osim.FreeJoint("free_" + lev.upper, model.getGround(), v3(centre), V(0),
                                      L4, v3(centre - c4), V(0)))
        disc = cs.disc
        # rotation bushing: frames parallel to the project axes at the disc centre
        rot = osim.ExpressionBasedBushingForce("disc_rotation", L5, v3(centre - c5), V(0),
                                               L4, v3(centre - c4), V(0))
        mx, my, mz = disc_moment_expressions(disc.torque, disc_mapping)
        rot.setMxExpression(mx)
        rot.setMyExpression(my)
        rot.setMzExpression(mz)
        for setter in (rot.setFxExpression, rot.setFyExpression, rot.setFzExpression):
            setter("0")
        rot.set_rotational_damping(V(rot_damping, rot_damping, rot_damping))
        rot.set_translational_damping(V(0, 0, 0))
        model.addForce(rot)
        # translation bushing: frames aligned with lumbar's disc frame (rows e1, e2, e3 = normal)
        E = disc_frame(lev.disc_normal).T          # columns e1, e2, e3 in the project frame
        eul = Rotation.from_matrix(E).as_euler("XYZ")   # body-fixed X-Y-Z, OpenSim's orientation Vec3
        tr = osim.ExpressionBasedBushingForce("disc_translation", L5, v3(centre - c5), v3(eul),
                                              L4, v3(centre - c4), v3(eul))
        fx, fy, fz = disc_force_expressions(disc.k_axial_quadratic, disc.k_axial_linear, disc.k_shear,
                                            disc.k_tension)
        tr.setFxExpression(fx)
        tr.setFyExpression(fy)
        tr.setFzExpression(fz)
        for setter in (tr.setMxExpression, tr.setMyExpression, tr.setMzExpression):
            setter("0")
        tr.set_rotational_damping(V(0, 0, 0))
        tr.set_translational_damping(V(trans_damping, trans_damping, trans_damping))
        model.addForce(tr)
        # ligament fibres
        self.fibres = []
        for lig in lev.ligaments:
            law = cs.ligaments.get(lig.kind)
            if law is None or lig.kind in gone:
                continue
            if not hasattr(law, "a"):
                raise NotImplementedError(f"only the softplus ligament law is mapped to OpenSim ({lig.kind})")
            n = len(lig.upper)
            extra = np.broadcast_to(np.asarray(lig.extra_length, float), (n,))
            for i in range(n):
                l_ref = np.linalg.norm(lig.upper[i] - lig.lower[i]) + extra[i]
                l0 = slack_length(l_ref, law.prestrain)
                expr = fibre_expression(law, l0, extra[i], 1.0 / n, slack_width_pct, fibre_damping / n)
                f = osim.ExpressionBasedPointToPointForce(lev.upper, v3(lig.upper[i] - c4),
                                                          lev.lower, v3(lig.lower[i] - c5), expr)
                f.setName(f"{lig.name}_{i}")
                model.addForce(f)
                self.fibres.append(f"{lig.name}_{i}")
        # pure moment on L4 in the ground (= project) frame
        pf = osim.PrescribedForce("pure_moment", L4)
        pf.setForceIsInGlobalFrame(True)
        self._torque = [osim.Constant(0.0) for _ in range(3)]
        pf.setTorqueFunctions(*self._torque)
        model.addForce(pf)
        self.model = model
        self.body = L4
        self.pure_moment = pf
        t = time.perf_counter()
        self.state = model.initSystem()
        self.time_init_s = time.perf_counter() - t
        self._torque = [osim.Constant.safeDownCast(pf.get_torqueFunctions().get(i)) for i in range(3)]
        self.integrator = integrator
        self.accuracy = accuracy
        # without a step cap RK-Merson's first step from rest overshoots into NaN (2 ms is safe)
        self.max_step_s = max_step_s
        self.rest = None

    # -------------------------------------------------------------- state helpers
    def pose(self, s):
        """(R (3,3), x (3,)) of L4 in ground: the project's body rotation and reference-point position."""
        self.model.realizePosition(s)
        X = self.body.getTransformInGround(s)
        Rm = X.R().asMat33()
        R = np.array([[Rm.get(i, j) for j in range(3)] for i in range(3)])
        p = X.p()
        return R, np.array([p.get(0), p.get(1), p.get(2)])

    def set_moment(self, M):
        for c, v in zip(self._torque, M):
            c.setValue(float(v))

    def equilibrium(self, M=(0.0, 0.0, 0.0), start=None, speed_tol=1e-6, chunk_s=0.005, max_time_s=10.0):
        """Forward-integrate under the constant moment M (project frame, N*m) until every generalised
        speed is below ``speed_tol`` (rad/s, m/s). Returns a dict with the final state and timings."""
        osim = self.osim
        self.set_moment(M)
        s = osim.State(self.state if start is None else start)
        if start is None:
            s.setQ(self.state.getQ())
        s.setU(osim.Vector(s.getNU(), 0.0))
        s.setTime(0.0)
        t0 = time.perf_counter()
        mgr = osim.Manager(self.model)
        mgr.setIntegratorMethod(getattr(osim.Manager, "IntegratorMethod_" + self.integrator))
        mgr.setIntegratorAccuracy(self.accuracy)
        mgr.setIntegratorMaximumStepSize(self.max_step_s)
        mgr.initialize(s)
        t_sim, converged, umax = 0.0, False, np.inf
        while t_sim < max_time_s:
            t_sim += chunk_s
            s = mgr.integrate(t_sim)
            u = s.getU()
            umax = max(abs(u.get(i)) for i in range(u.size()))
            if not np.isfinite(umax):
                break
            if umax < speed_tol:
                converged = True
                break
        wall = time.perf_counter() - t0
        return {"state": osim.State(s), "converged": converged, "sim_time_s": t_sim, "wall_s": wall,
                "max_speed": umax}

    def settle_rest(self, **kw):
        r = self.equilibrium((0.0, 0.0, 0.0), **kw)
        self.rest = r
        return r


def opensim_side(osim, geo, cs, case="wo_va", moments=MOMENTS_NM, directions=MAIN_DIRECTIONS,
                 disc_mapping="exact", speed_tol=1e-6, **kw):
    fsu = OpenSimFSU(osim, geo, cs, case, disc_mapping=disc_mapping, **kw)
    rest = fsu.settle_rest(speed_tol=speed_tol)
    R0, x0 = fsu.pose(rest["state"])
    rows = []
    for d, Mag in scenario_grid(moments, directions):
        ax, sg = DIRECTIONS[d]
        M = np.zeros(3)
        M[ax] = sg * Mag
        r = fsu.equilibrium(M, start=rest["state"], speed_tol=speed_tol)
        R, x = fsu.pose(r["state"])
        if not (r["converged"] and np.isfinite(R).all() and np.isfinite(x).all()):
            R, x = np.full((3, 3), np.nan), np.full(3, np.nan)
            rot = np.full(3, np.nan)
        else:
            rot = so3.log(R @ R0.T)
        rows.append({"direction": d, "moment_nm": Mag, "rom_deg": float(np.degrees(rot[ax] * sg)),
                     "rot_deg": np.degrees(rot).tolist(), "trans_mm": ((x - x0) * 1e3).tolist(),
                     "converged": r["converged"], "wall_s": r["wall_s"], "sim_time_s": r["sim_time_s"],
                     "max_speed": r["max_speed"]})
    return {"model": fsu, "rows": rows, "rest": rest, "R0": R0, "x0": x0}


# ------------------------------------------------------------------ side by side
def side_by_side(case="wo_va", moments=MOMENTS_NM, directions=MAIN_DIRECTIONS, disc_mapping="exact",
                 repeat=5, speed_tol=1e-6, geo=None, cs=None, n_large=1000, **opensim_kw):
    osim, reason = import_opensim()
    if osim is None:
        return {"benchmark": "opensim_side_by_side", "skipped": True, "reason": reason}
    if geo is None or cs is None:
        geo, cs = load_case()
    lum = lumbar_side(geo, cs, case, moments, directions, repeat, n_large=n_large)
    ops = opensim_side(osim, geo, cs, case, moments, directions, disc_mapping, speed_tol, **opensim_kw)
    tab = lum["table"]
    scen = []
    for i, row in enumerate(ops["rows"]):
        rl = float(lum["rom_deg"][i])
        scen.append({
            "direction": row["direction"], "moment_nm": row["moment_nm"],
            "rom_lumbar_deg": round(rl, 5), "rom_opensim_deg": round(row["rom_deg"], 5),
            "diff_deg": float(f"{row['rom_deg'] - rl:.3g}"),
            "coupled_rot_lumbar_deg": [round(float(tab[c].iloc[i]), 4) for c in ("rot_x_deg", "rot_y_deg", "rot_z_deg")],
            "coupled_rot_opensim_deg": [round(v, 4) for v in row["rot_deg"]],
            "trans_lumbar_mm": [round(float(tab[c].iloc[i]), 4) for c in ("trans_x_mm", "trans_y_mm", "trans_z_mm")],
            "trans_opensim_mm": [round(v, 4) for v in row["trans_mm"]],
            "lumbar_converged": bool(lum["converged"][i]), "opensim_settled": bool(row["converged"]),
            "opensim_wall_s": round(row["wall_s"], 4), "opensim_sim_time_s": round(row["sim_time_s"], 3),
        })
    diffs = np.array([s["diff_deg"] for s in scen], float)   # NaN where OpenSim did not settle
    t_os = float(np.mean([r["wall_s"] for r in ops["rows"]]))
    fsu = ops["model"]
    out = {
        "benchmark": "opensim_side_by_side", "skipped": False,
        "opensim_version": osim.__version__, "opensim_build": osim.GetVersionAndDate(),
        "geometry": f"{geo.name} L4-L5", "characteristic_set": "calibrated",
        "lumbar_kernel": kernel.mode() if kernel.active() else "reference (numba missing)",
        "structures": STRUCTURES,
        "case": case, "lumbar_stage": CASES[case][0], "elements_compared": CASES[case][1],
        "disc_mapping": disc_mapping,
        "scenarios": scen,
        "max_abs_diff_deg": float(f"{np.abs(diffs).max():.3g}"),   # NaN if any scenario failed
        "tolerance_deg": 0.1, "agree_within_tolerance": bool(np.all(np.abs(diffs) < 0.1)),
        "time_per_equilibrium_lumbar_batch_s": lum["time_batch_s"],
        "time_per_equilibrium_lumbar_single_s": lum["time_single_s"],
        "time_per_equilibrium_lumbar_large_batch_s": lum["time_large_batch_s"],
        "lumbar_large_batch_size": lum["n_large"], "lumbar_large_batch_converged": lum["large_batch_converged"],
        "time_per_equilibrium_opensim_s": t_os,
        "opensim_integrator": f"{fsu.integrator} (accuracy {fsu.accuracy:g}, max step {fsu.max_step_s:g} s)",
        "opensim_rest_state_s": round(ops["rest"]["wall_s"], 4),
        "opensim_model_init_s": round(fsu.time_init_s, 4),
        "small_batch_size": len(scen),
        "speedup_batch": round(t_os / lum["time_batch_s"], 1),
        "speedup_small_batch": round(t_os / lum["time_batch_s"], 1),
        "speedup_single": round(t_os / lum["time_single_s"], 1),
        "speedup_single_solve_only": round(t_os / lum["time_single_solve_only_s"], 1),
        "speedup_large_batch": round(t_os / lum["time_large_batch_s"], 1),
        "target_speedup_large_batch": TARGET_SPEEDUP_LARGE_BATCH, "target_speedup_single": TARGET_SPEEDUP_SINGLE,
        "meets_targets": bool(t_os / lum["time_large_batch_s"] >= TARGET_SPEEDUP_LARGE_BATCH
                              and t_os / lum["time_single_s"] >= TARGET_SPEEDUP_SINGLE),
        "load_average_1_5_15_min": [round(v, 2) for v in os.getloadavg()],
        "notes": [
            "Facet contact is NOT compared: OpenSim has no equivalent of the facet regression-surface contact "
            "(see structures); stage w/o VA has no facets (and the intact_no_facets case builds lumbar with "
            "facet_stiffness=0 and OpenSim without facets).",
            "Same constitutive laws in both engines: disc Eq. 3 per project axis on the rotation vector of "
            "L4 relative to L5 (flexion/extension split by its sign), compression-only axial law and linear "
            "shear in the disc frame; softplus Eq. 7 fibres with prestrain (slack length = reference length "
            "/ (1 + prestrain)), tension-only with the same 0.5 % C1 slack ramp, force shared by the fibres.",
            f"disc_mapping={disc_mapping}: 'exact' evaluates lumbar's rotation vector from OpenSim's body-fixed "
            "XYZ bushing angles and maps the torque to the angles' generalised forces; 'naive' applies Eq. 3 "
            "to each Euler angle.",
            "OpenSim equilibria by forward dynamics (integrator "
            f"{fsu.integrator}, accuracy {fsu.accuracy:g}) from the 0 N*m rest state until all speeds < "
            f"{speed_tol:g}; L4 mass {L4_MASS_KG} kg, inertia {L4_INERTIA_KGM2} kg m^2 and the bushing/fibre "
            "damping only shape the transient; statics do not depend on them.",
            "lumbar batch time (small batch, small_batch_size scenarios) = one range_of_motion call (rest solve + "
            "all scenarios in one batched Newton) / number of scenarios; large batch = the same scenarios tiled to lumbar_large_batch_size in one "
            "batched Newton solve from the rest state / that size; single = one Newton solve per scenario from the rest state plus the rest "
            "solve shared out; OpenSim time = wall time of one forward integration to rest per scenario "
            "(model building and the rest state excluded). Best of repeats for lumbar, one core each.",
        ],
    }
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--case", default="wo_va", choices=sorted(CASES))
    p.add_argument("--disc-mapping", default="exact", choices=("exact", "naive"))
    p.add_argument("--moments", type=float, nargs="+", default=list(MOMENTS_NM))
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--speed-tol", type=float, default=1e-6)
    p.add_argument("--integrator", default="RungeKuttaMerson",
                   help="OpenSim Manager integrator (CPodes, RungeKuttaMerson, ...)")
    p.add_argument("--accuracy", type=float, default=1e-7,
                   help="OpenSim integrator accuracy (1e-5 chatters at the ISL toe in intact_no_facets)")
    p.add_argument("--max-step", type=float, default=2e-3, help="OpenSim maximum step [s]")
    p.add_argument("--n-large", type=int, default=1000, help="lumbar large-batch size")
    p.add_argument("--out", default=None, help="also write the JSON here")
    a = p.parse_args(argv)
    out = side_by_side(a.case, tuple(a.moments), MAIN_DIRECTIONS, a.disc_mapping, a.repeat, a.speed_tol,
                       n_large=a.n_large, integrator=a.integrator, accuracy=a.accuracy, max_step_s=a.max_step)
    text = json.dumps(out, indent=2)
    print(text)
    if a.out and not out.get("skipped"):
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(a.out).with_suffix(".tmp")
        tmp.write_text(text + "\n")
        tmp.replace(a.out)
    return out


if __name__ == "__main__":
    main()
    sys.exit(0)
