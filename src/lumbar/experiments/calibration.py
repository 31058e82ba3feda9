"""Backward calibration of the L4-L5 unit on a stepwise-reduction ROM table (paper 1, Sect. 2.2.2-2.2.4, 3.1.1).

The reduction experiment is replayed backwards; each structure is fitted on the stage in which it is
the newest structure present (every other structure of that stage is already calibrated):

=====  =========================  ===========  ==============================================
step   structure                  fit stage    parameters
=====  =========================  ===========  ==============================================
1      disc (Eq. 3, per direction) ``wo_all``  p1, p2, p3 per direction (flexion, extension,
                                                lateral_bending, axial_rotation): T(phi_meas) = M
2      ALL (Eq. 7)                ``wo_pll``   a, b, d
3      PLL                        ``wo_va``    a, b, d
4      facet stiffness (Eq. 5)    ``wo_cl``    c_stiff (the facets go with the vertebral arch;
                                                the ITL goes too but has no Table 3 row: the
                                                calibrated set keeps the ITL absent, as the paper)
5      CL                         ``wo_fl``    a, b, d
6      FL                         ``wo_isl``   a, b, d
7      ISL                        ``wo_ssl``   a, b, d
8      SSL                        ``intact``   a, b, d
=====  =========================  ===========  ==============================================

Disc (step 1): the disc-only unit is in equilibrium where the disc torque equals the applied moment,
so Eq. 3 is fitted to the points (phi = measured mean ROM, T = M) by ``least_squares(method="trf")``;
start values from a grid over p2 with p1, p3 solved linearly (variable projection), then refined.
Lateral bending and axial rotation are symmetric (one law each), flexion and extension separate.

Ligaments (steps 2-8): Eq. 7 has four parameters, but (a, b, c, d) are not identifiable from ROM
(a shift of c trades against a and b). Project parametrisation: ``c = -a*ln(1 + exp(b/d))`` so that the
law is zero at 0 % strain (F(0) = 0, tension-only rule of ``lumbar.mechanics.elements.ligament`` unchanged), and
(a, b, d) are fitted with bounds a in [0.01, 5000] N, b in [-60, 40] %, d in [0.05, 50] % (d > 0:
monotone laws; the paper's concave FL, d < 0, is outside this family by design). The prestrains stay the
paper's (Sect. 2.2.4). Each fit is a ``least_squares(method="trf")`` with finite differences over that
stage's 20 scenarios (5 moments x 4 directions); each evaluation solves the stage's FSU batch (warm
started). Residual = (ROM_sim - ROM_mean) / width with width = max - min where the row has a range,
else 2 x ``tolerance_deg``; a scenario without equilibrium contributes a fixed penalty of 10.

The facet stiffness (step 4) is one parameter (log-scaled, bounds 100 N/m - 1e6 N/m).
This module never imports snakemake.
"""
from __future__ import annotations

import copy
import dataclasses
import logging
import math
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import brentq, least_squares

from ..inputs.characteristics import SoftplusLaw, load_characteristic_set, load_shape_check
from ..mechanics.elements.ligament import softplus_force
from . import admissibility as ADM
from .fsu import MIN_SLACK_FRACTION, build_fsu, facet_surfaces, moment_loads, set_ligament_law
from .load_sharing import AXIS_OF, level_structures
from .posterior import Posterior, laplace_posterior
from .priors import default_spreads
from ..inputs.io import save_figure_atomic, subplots, write_table_atomic
from .stepwise_reduction import MAIN_DIRECTIONS, StageSolver
from ..mechanics import so3
from ..geometry.visible_human import uw_force
from ..mechanics.solve import solve, solve_sequence

log = logging.getLogger(__name__)

DISC_STAGE = "wo_all"
FACET_STAGE = "wo_cl"
LIGAMENT_STAGE = {"ALL": "wo_pll", "PLL": "wo_va", "CL": "wo_fl", "FL": "wo_isl", "ISL": "wo_ssl", "SSL": "intact"}
ORDER = [("disc", DISC_STAGE), ("ALL", "wo_pll"), ("PLL", "wo_va"), ("facets", FACET_STAGE),
         ("CL", "wo_fl"), ("FL", "wo_isl"), ("ISL", "wo_ssl"), ("SSL", "intact")]
CALIBRATED_LIGAMENTS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL")
A_BOUNDS, B_BOUNDS, D_BOUNDS = (0.01, 5000.0), (-60.0, 40.0), (0.05, 50.0)
K_FACET_BOUNDS = (100.0, 1.0e7)
F0_BOUNDS = (0.0, 300.0)
CONCAVE_CANDIDATES = ("FL",)
PENALTY = 10.0


def c_zero(a, b, d):
    """c of Eq. 7 such that F(0 %) = 0."""
    return -a * float(np.logaddexp(0.0, b / d))


def softplus_zero_law(eps_pct, a, b, d):
    """Eq. 7 with c = c_zero(a, b, d) (raw law, no tension-only rule) [N]."""
    return a * (np.logaddexp(0.0, (np.asarray(eps_pct, float) + b) / d) - np.logaddexp(0.0, b / d))


def eq3(phi_rad, p):
    p1, p2, p3 = p
    return p1 * np.tanh(np.asarray(phi_rad) ** 3 / p2) + p3 * np.asarray(phi_rad)


# ------------------------------------------------------------------ disc
#: smallest p1 [N*m] of Eq. 3 a disc fit may take: the tanh term is the law's stiffening term (the paper's Table 1
#: has p1 > 0 in every direction); a negative p1 makes a law that is stiffest at zero and softens with the load, the
#: opposite of a disc (measured: a table with a neutral-zone laxity drove the free fit of flexion to p1 = -7.6 N*m,
#: p3 = +58 N*m/rad). At the bound (flagged ``at_bound``) the rows show no stiffening and the law is linear.
P1_MIN_NM = 0.0


def fit_disc_direction(phi_rad, torque_nm):
    """Eq. 3 parameters (p1 [N*m], p2 [rad^3], p3 [N*m/rad]) with T(phi) = torque, least squares (trf) with
    p1 >= :data:`P1_MIN_NM` (p3 is free: the paper's flexion law has p3 < 0)."""
    phi = np.asarray(phi_rad, float)
    M = np.asarray(torque_nm, float)
    ok = np.isfinite(phi) & np.isfinite(M)
    phi, M = phi[ok], M[ok]
    if phi.size < 3:
        raise ValueError(f"disc fit needs >= 3 finite (ROM, moment) points, got {phi.size}")
    best = None
    for lp2 in np.linspace(-8, 0, 81):          # variable projection start: p1, p3 linear for fixed p2
        p2 = 10.0 ** lp2
        A = np.column_stack([np.tanh(phi**3 / p2), phi])
        (p1, p3), *_ = np.linalg.lstsq(A, M, rcond=None)
        if p1 < P1_MIN_NM:                      # the linear law alone, p1 at its bound
            p1 = P1_MIN_NM
            p3 = float(np.linalg.lstsq(A[:, 1:], M - p1 * A[:, 0], rcond=None)[0][0])
        r = float(np.sum((A @ [p1, p3] - M) ** 2))
        if best is None or r < best[0]:
            best = (r, (p1, p2, p3))
    p0 = np.array(best[1])

    def res(q):
        return eq3(phi, (q[0], 10.0 ** q[1], q[2])) - M

    sol = least_squares(res, [p0[0], math.log10(p0[1]), p0[2]], method="trf",
                        bounds=([P1_MIN_NM, -9, -1e3], [1e3, 1, 1e3]), x_scale=[1.0, 0.1, 1.0],
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000)
    return float(sol.x[0]), float(10.0 ** sol.x[1]), float(sol.x[2])


# ------------------------------------------------------------------ result container
@dataclass
class CalibrationResult:
    charset: object                                  # CharacteristicSet with the fitted values
    disc: dict                                       # direction -> (p1, p2, p3)
    facet_stiffness: float                           # N/m
    ligaments: dict                                  # kind -> (a, b, c, d) [N, %]
    summary: pd.DataFrame                            # one row per calibration step
    rom_fit: pd.DataFrame                            # per scenario: simulated vs reference at the fit stage
    disc_points: pd.DataFrame                        # Fig. 4 data
    ligament_points: pd.DataFrame                    # Fig. 5 data
    facet_surfaces: pd.DataFrame                     # Table 2 data (Eq. 4 coefficients per side)
    data_kind: str = "surrogate"
    wall_time_s: float = 0.0
    info: dict = field(default_factory=dict)


def _replace(obj, **kw):
    if dataclasses.is_dataclass(obj):
        return dataclasses.replace(obj, **kw)
    out = copy.copy(obj)
    for k, v in kw.items():
        setattr(out, k, v)
    return out


def _kind_groups(model, kind):
    return [g for g, (_, k, _) in enumerate(model.fibre_groups) if k == kind]


def _set_law(model, kind, a, b, d, law_length_m=None, prestrain_pct=0.0):
    set_ligament_law(model, _kind_groups(model, kind),
                     SoftplusLaw(a, b, c_zero(a, b, d), d, prestrain_pct, law_length_m=law_length_m))


def _stage_rows(ref, stage):
    r = ref[ref["stage"] == stage].reset_index(drop=True)
    if r.empty:
        raise ValueError(f"reference table has no rows for stage {stage!r} (needed to calibrate it)")
    return r


def _widths(rows, tolerance_deg):
    lo, hi = rows["rom_min_deg"].to_numpy(float), rows["rom_max_deg"].to_numpy(float)
    w = np.where(np.isfinite(lo) & np.isfinite(hi), hi - lo, 2.0 * tolerance_deg)
    return np.maximum(w, 0.05)


def _real_fit_step(fit, step, structure, targets) -> dict:
    """One calibration_summary row for a :func:`fit_real_targets` step."""
    err = fit.targets["rom_sim_deg"] - fit.targets["rom_mean_deg"]
    bound = fit.parameters[fit.parameters["at_bound"]]["parameter"].tolist()
    return {"step": step, "structure": structure, "stage": ",".join(sorted(set(targets["stage"]))),
            "n_scenarios": len(targets),
            "parameters": "; ".join(f"{r.parameter}={r.value:.4g} {r.unit}" for r in fit.parameters.itertuples()),
            "rms_residual": float(np.sqrt(np.nanmean(err ** 2))), "residual_unit": "deg",
            "n_not_converged": int((~fit.targets["converged"]).sum()), "n_evaluations": fit.n_evaluations,
            "identifiable": bool(fit.parameters["identifiable"].any()), "at_bound": bool(bound),
            "at_bound_parameters": ";".join(bound)}


def calibrate(geometry, reference: pd.DataFrame, initial=None, level="L4-L5", k_shear=None,
              tolerance_deg=0.5, data_kind="surrogate", max_iter=50, tol=1e-7, max_nfev=60,
              start=None, concave=CONCAVE_CANDIDATES, surrogate_weight=1.0,
              real_targets: pd.DataFrame | None = None, real_fit_kw=None, family="monotone",
              anchor_start=True, final_surrogate_weight=0.0, transfer="strain", geometry_path=None,
              anchor_start_values: dict | None = None, prior="remus2021") -> CalibrationResult:
    """Calibrate disc, facet stiffness and ligaments on ``reference`` (see module doc).

    ``family``: the ligament law family of steps 2-8. "monotone" (module doc: a, b, d fitted with F(0) = 0,
    d > 0, plus a concave branch for the FL); "scaled_published": the ``initial`` set's law of each ligament
    (the paper's Table 3, the published shape, prestrain and sign of d kept) with two fitted parameters, a
    force scale s (a -> s a, c -> s c; log10 s in [-3, 1]) and a knee shift (b -> b + db, db in [-20, 20] %).
    The latter contains the published laws (s = 1, db = 0), so a surrogate generated from (a force-scaled)
    published set can be recovered (round trip), which the monotone family cannot do for the paper's
    concave FL.
    ``anchor_start`` (with ``real_targets``): step 0 fits the ``initial`` set's force scales, facet stiffness
    and disc shear stiffness to the real rows (:func:`fit_real_targets`, the same fit that anchors the
    surrogate generator) and the stepwise steps start from that set.
    ``final_surrogate_weight``: in the final joint step, the other reference rows together count this many
    times as much as the real rows together; 0 (default): the final set is fixed by the real rows alone (on
    the Visible Human unit, measured on the test configuration, any weight > 0 pulled the intact ROM 15-45 %
    off the real rows: the surrogate stages come from jittered virtual specimens of this same model and carry
    no information about real specimens).
    ``surrogate_weight``: weight of the residual of reference rows with ``kind == "surrogate"`` relative to
    real rows (weight 1): real data, where the reference has them, dominate the stepwise fits.
    ``real_targets``: real ROM rows (stage, direction, moment_nm, rom_mean_deg), e.g. the intact ROM of
    Yamamoto et al. (1989); after the stepwise steps, :func:`fit_real_targets` refines force scales of
    the calibrated set on them (summary step ``real_targets``; its parameters are listed one per row in
    ``info["real_fit"]``).
    Every step records ``identifiable`` (a structure whose parameters change no ROM of its fit stage by
    ``IDENTIFIABLE_MIN_DEG`` per step is not fitted: it keeps the ``initial`` set's law, e.g. a ligament
    that stays slack) and ``at_bound`` (a fitted parameter within ``AT_BOUND_FRACTION`` of a bound).

    ``initial``: characteristic set providing everything that is not fitted (axial disc law, shear
    stiffness, prestrains, damping); default ``load_characteristic_set("calibrated")``.
    ``start``: optional {kind: (a, b, d)} start values of the ligament fits (default a = 20 N,
    b = -prestrain, d = 2 %: the knee at the reference length).
    ``transfer``: how the ligament laws reach this geometry. "strain" (the paper's rule: Eq. 7 in percent of each
    fibre's own slack length; the real-target steps are :func:`fit_real_targets`); "elongation": the calibration
    starts from :func:`elongation_prior` (every law on elongation in percent of the paper's fibre length, the FL and
    ITL from the paper's Rupp characteristic) and the real-target steps (step 0 and the final one) are
    :func:`fit_admissible` (real rows plus the physical-admissibility criteria), started from
    ``anchor_start_values`` (parameter -> fit value, e.g. the surrogate generator's anchoring) when given.
    """
    t0 = time.perf_counter()
    published = initial if initial is not None else load_characteristic_set("calibrated")
    base = published
    steps = []
    info = {}
    if transfer not in ("strain", "elongation"):
        raise ValueError(f"ligament transfer {transfer!r}; expected 'strain' or 'elongation'")
    spreads = {}
    if transfer == "elongation":
        base, info["prior"], spreads = calibration_prior(published, geometry, level, geometry_path, prior)
        info["prior_set"] = base
        info["prior_name"] = prior if spreads else "table3"
        info["prior_spreads"] = spreads
    # ---- step 0: the start set anchored on the real rows (the same fit as the surrogate generator's)
    if real_targets is not None and len(real_targets) and anchor_start:
        if transfer == "elongation":
            a0 = fit_admissible(geometry, base, real_targets, level=level, published=published,
                                geometry_path=geometry_path, k_shear=k_shear, max_iter=max_iter,
                                start=anchor_start_values, prior_spread=spreads, **(real_fit_kw or {}))
            info["anchor_fit"] = a0
        else:
            a0 = fit_real_targets(geometry, base, real_targets, level=level, k_shear=k_shear, max_iter=max_iter,
                                  **(real_fit_kw or {}))
        base = a0.charset
        info["anchor"] = a0.parameters
        steps.append(_real_fit_step(a0, 0, "start_set_on_real_targets", real_targets))
    # ---- step 1: disc
    rows = _stage_rows(reference, DISC_STAGE)
    torque = dict(base.disc.torque)
    disc_pts = []
    for d in MAIN_DIRECTIONS:
        r = rows[rows["direction"] == d]
        if len(r) < 3:
            raise ValueError(f"stage {DISC_STAGE}: direction {d!r} has {len(r)} rows; the disc fit needs >= 3")
        phi = np.radians(r["rom_mean_deg"].to_numpy(float))
        M = r["moment_nm"].to_numpy(float)
        p = fit_disc_direction(phi, M)
        torque[d] = p
        for ph, m in zip(phi, M):
            disc_pts.append({"direction": d, "moment_nm": m, "rom_deg": math.degrees(ph),
                             "torque_fit_nm": float(eq3(ph, p))})
        resid = eq3(phi, p) - M
        p1_bound = p[0] <= P1_MIN_NM + 1e-9
        if p1_bound:
            log.info("calibration step 1 (disc %s): p1 at its bound %g N*m: the rows show no stiffening, the law is "
                     "linear (p3 = %.4g N*m/rad)", d, P1_MIN_NM, p[2])
        steps.append({"step": 1, "structure": f"disc:{d}", "stage": DISC_STAGE, "n_scenarios": len(r),
                      "parameters": "p1,p2,p3", "rms_residual": float(np.sqrt(np.mean(resid**2))),
                      "residual_unit": "N*m", "n_not_converged": 0, "n_evaluations": 1,
                      "identifiable": True, "at_bound": bool(p1_bound), "at_bound_parameters": "p1" if p1_bound else ""})
    disc = _replace(base.disc, torque=torque)
    # ---- model with every calibrated ligament (start values); unfitted ones are masked by the stages
    start = dict(start or {})
    ligs = {}
    if family not in ("monotone", "scaled_published"):
        raise ValueError(f"calibration family {family!r}; expected 'monotone' or 'scaled_published'")
    for kind in CALIBRATED_LIGAMENTS:
        pre = base.ligaments[kind].prestrain_pct if kind in base.ligaments else 0.0
        pub = base.ligaments.get(kind)
        if family == "scaled_published" and pub is not None and hasattr(pub, "a"):
            ligs[kind] = _replace(pub, source="calibration start (published law)")
            continue
        a, b, d = start.get(kind, (20.0, -pre, 2.0))
        ligs[kind] = SoftplusLaw(a, b, c_zero(a, b, d), d, pre, source="calibration start",
                                 law_length_m=getattr(pub, "law_length_m", None))
    extra = {k: v for k, v in base.ligaments.items() if k not in CALIBRATED_LIGAMENTS}   # e.g. the ITL on elongation
    cs = _replace(base, name="calibrated", disc=disc, ligaments={**ligs, **extra},
                  absent={} if "ITL" in extra else
                  {"ITL": "no Table 3 row; the stepwise-reduction experiment does not isolate the ITL"})
    k_fac0 = float(base.facet.stiffness)
    fsu = build_fsu(geometry, cs, level, facet_stiffness=k_fac0, k_shear=k_shear)
    m = fsu.model
    k_stiff0 = m.k_stiff.copy()
    fitted = {}
    rom_fit, lig_pts = [], []
    k_fac = k_fac0
    for step, (what, stage) in enumerate(ORDER[1:], start=2):
        rows = _stage_rows(reference, stage)
        w = _widths(rows, tolerance_deg)
        if "kind" in rows.columns:
            w = w / np.where(rows["kind"].to_numpy() == "surrogate", float(surrogate_weight), 1.0)
        target = rows["rom_mean_deg"].to_numpy(float)
        ss = StageSolver(fsu, rows[["stage", "direction", "moment_nm"]], max_iter=max_iter, tol=tol)
        n_eval = [0]

        def residual(q, apply):
            apply(q)
            n_eval[0] += 1
            rom, conv, _ = ss.run()
            return np.where(conv, (rom - target) / w, PENALTY)

        candidates = []
        if what == "facets":
            def apply_f(q):
                m.k_stiff[:] = k_stiff0 * (10.0 ** q[0] / k_fac0)
            candidates.append((apply_f, [math.log10(k_fac)], [math.log10(K_FACET_BOUNDS[0])],
                               [math.log10(K_FACET_BOUNDS[1])], [0.3], None))
        else:
            kind = what
            law = ligs[kind]
            if family == "scaled_published":
                def apply_s(q, kind=kind, law=law):     # published shape: force scale and knee shift
                    sc = 10.0 ** q[0]
                    set_ligament_law(m, _kind_groups(m, kind), _replace(law, a=law.a * sc, b=law.b + q[1],
                                                                        c=law.c * sc))
                candidates.append((apply_s, [0.0, 0.0], [-3.0, -20.0], [1.0, 20.0], [0.3, 2.0],
                                   lambda q, law=law: (law.a * 10.0 ** q[0], law.b + q[1], law.c * 10.0 ** q[0],
                                                       law.d)))

            def apply_m(q, kind=kind, law=law):  # monotone branch: d > 0, F(0) = 0
                _set_law(m, kind, 10.0 ** q[0], q[1], 10.0 ** q[2], law.law_length_m, law.prestrain_pct)
            if family == "scaled_published":
                law = _replace(law, a=20.0, b=-law.prestrain_pct, d=2.0)   # unused: only candidate 0 is fitted
            candidates.append((apply_m, [math.log10(law.a), law.b, math.log10(law.d)],
                               [math.log10(A_BOUNDS[0]), B_BOUNDS[0], math.log10(D_BOUNDS[0])],
                               [math.log10(A_BOUNDS[1]), B_BOUNDS[1], math.log10(D_BOUNDS[1])], [0.3, 2.0, 0.3],
                               lambda q: (10.0 ** q[0], q[1], c_zero(10.0 ** q[0], q[1], 10.0 ** q[2]), 10.0 ** q[2])))
            if kind in concave:
                def apply_c(q, kind=kind, law=law):  # concave branch: d < 0, F(0) = F0 >= 0 fitted
                    a, b, d, f0 = 10.0 ** q[0], q[1], -(10.0 ** q[2]), q[3]
                    set_ligament_law(m, _kind_groups(m, kind), _replace(law, a=a, b=b, c=f0 + c_zero(a, b, d), d=d))
                candidates.append((apply_c, [1.5, 0.0, 1.0, 50.0],
                                   [math.log10(A_BOUNDS[0]), B_BOUNDS[0], math.log10(D_BOUNDS[0]), F0_BOUNDS[0]],
                                   [math.log10(A_BOUNDS[1]), B_BOUNDS[1], math.log10(D_BOUNDS[1]), F0_BOUNDS[1]],
                                   [0.3, 2.0, 0.3, 20.0],
                                   lambda q: (10.0 ** q[0], q[1],
                                              q[3] + c_zero(10.0 ** q[0], q[1], -(10.0 ** q[2])), -(10.0 ** q[2]))))
        if family == "scaled_published":
            candidates = candidates[:1]
        # identifiability: does a step of every parameter change the stage's ROM at all?
        apply0, x00, lb0, ub0, xs0 = candidates[0][:5]
        x00 = np.clip(x00, lb0, ub0)
        r_base = residual(x00, apply0) * w
        identifiable = False
        for j in range(len(x00)):
            dq = np.array(x00, float)
            dq[j] = dq[j] + (xs0[j] if dq[j] + xs0[j] <= ub0[j] else -xs0[j])
            if np.nanmax(np.abs(residual(dq, apply0) * w - r_base)) >= IDENTIFIABLE_MIN_DEG:
                identifiable = True
                break
        at_bound = []
        if not identifiable:
            if what == "facets":
                m.k_stiff[:] = k_stiff0 * (k_fac0 / k_fac0)
            else:
                pub = base.ligaments.get(what)
                if pub is not None and hasattr(pub, "a"):
                    set_ligament_law(m, _kind_groups(m, what), pub)
            log.info("calibration step %d (%s on %s): not identifiable (no ROM of the stage changes by %.2g "
                     "deg when its parameters change): kept at the start set's value", step, what, stage,
                     IDENTIFIABLE_MIN_DEG)
        else:
            best = None
            for apply, x0, lb, ub, xs, to_law in candidates:
                x0 = np.clip(x0, lb, ub)
                sol = least_squares(lambda q: residual(q, apply), x0, method="trf", bounds=(lb, ub), x_scale=xs,
                                    diff_step=1e-5, xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=max_nfev)
                if best is None or sol.cost < best[0].cost - 1e-12:
                    best = (sol, apply, to_law, np.asarray(lb, float), np.asarray(ub, float))
            sol, apply, to_law, lb, ub = best
            apply(sol.x)
            span = ub - lb
            at_bound = [j for j in range(len(sol.x))
                        if sol.x[j] - lb[j] <= AT_BOUND_FRACTION * span[j] or ub[j] - sol.x[j] <= AT_BOUND_FRACTION * span[j]]
        rom, conv, res = ss.run()
        if not identifiable:
            if what == "facets":
                params = f"c_stiff={k_fac:.6g} N/m (not identifiable: start value)"
            else:
                pub = base.ligaments.get(what)
                fitted[what] = (pub.a, pub.b, pub.c, pub.d) if pub is not None and hasattr(pub, "a") else \
                    tuple(float(v) for v in (ligs[what].a, ligs[what].b, ligs[what].c, ligs[what].d))
                params = "a={:.5g} N, b={:.5g} %, c={:.5g} N, d={:.5g} % (not identifiable: start set)".format(
                    *fitted[what])
        elif what == "facets":
            k_fac = 10.0 ** sol.x[0]
            params = f"c_stiff={k_fac:.6g} N/m"
        else:
            fitted[what] = tuple(float(v) for v in to_law(sol.x))
            params = "a={:.5g} N, b={:.5g} %, c={:.5g} N, d={:.5g} %".format(*fitted[what])
            # Fig. 5 data: group strain and force at the stage's solutions (and its 0 N*m state)
            _, strain, *_ = m.fibre_state(res.x, res.R)
            gf = m.group_forces(res.x, res.R)
            for g in _kind_groups(m, what):
                sel = m.f_group == g
                for i in range(len(rows)):
                    if conv[i]:
                        lig_pts.append({"ligament": what, "group": m.fibre_groups[g][0], "stage": stage,
                                        "direction": rows["direction"][i], "moment_nm": rows["moment_nm"][i],
                                        "strain_pct": float(strain[i, sel].mean()), "force_n": float(gf[i, g])})
        err = rom - target
        names = ["log10 c_stiff"] if what == "facets" else (
            ["log10 force scale", "knee shift db"] if family == "scaled_published" else ["log10 a", "b", "log10 |d|", "F0"])
        steps.append({"step": step, "structure": what, "stage": stage, "n_scenarios": len(rows),
                      "parameters": params, "rms_residual": float(np.sqrt(np.nanmean(err**2))),
                      "residual_unit": "deg", "n_not_converged": int((~conv).sum()), "n_evaluations": n_eval[0],
                      "identifiable": identifiable, "at_bound": bool(at_bound),
                      "at_bound_parameters": ";".join(names[j] for j in at_bound)})
        log.info("calibration step %d (%s on %s): %s; rms ROM error %.4f deg, %d evaluations",
                 step, what, stage, params, steps[-1]["rms_residual"], n_eval[0])
        rom_fit.append(pd.DataFrame({"structure": what, "stage": stage, "direction": rows["direction"],
                                     "moment_nm": rows["moment_nm"], "rom_sim_deg": rom,
                                     "rom_mean_deg": target, "converged": conv}))
    # ---- final set
    final_ligs = {k: SoftplusLaw(*fitted[k], ligs[k].prestrain_pct, source=f"calibrated on {LIGAMENT_STAGE[k]}",
                                 law_length_m=ligs[k].law_length_m)
                  for k in CALIBRATED_LIGAMENTS}
    facet = _replace(base.facet, stiffness=k_fac)
    cal = _replace(cs, ligaments={**final_ligs, **extra}, facet=facet, alternatives={})
    if real_targets is not None and len(real_targets):
        # start of the final joint fit: the start set anchored on the real rows (step 0) with the fitted disc,
        # when the stepwise family contains it; the stepwise laws otherwise. On the short-fibre Visible Human
        # unit the stepwise fits drift (measured: knee shifts at their bounds, intact ROM 30-40 % off the
        # real rows), while the anchored set already meets the real rows: the joint fit then only trades it
        # against the surrogate stages (weight surrogate_weight) and the derived disc-only rows.
        final_start = cal
        if "anchor" in info and family == "scaled_published":
            final_start = _replace(base, name="calibrated", disc=cal.disc, absent=cal.absent, alternatives={})
            info["final_start"] = "start set anchored on the real rows (step 0)"
        else:
            info["final_start"] = "stepwise result"
        if transfer == "elongation":
            # the final set: the admissible fit again, with the fitted disc, from the step-0 optimum (the prior's
            # laws are its reference: scales and pre-elongation changes are relative to the prior)
            prior_set = _replace(info["prior_set"], disc=_replace(cal.disc, k_shear=info["prior_set"].disc.k_shear))
            a0 = info.get("anchor_fit")
            st = None if a0 is None else dict(zip(a0.parameters["parameter"], a0.parameters["fit_value"]))
            rf = fit_admissible(geometry, prior_set, real_targets, level=level, published=published,
                                geometry_path=geometry_path, k_shear=k_shear, max_iter=max_iter, start=st,
                                prior_spread=spreads, disc_rows=_stage_rows(reference, DISC_STAGE),
                                **(real_fit_kw or {}))
            info["final_fit"] = rf
        else:
            rf = fit_real_targets(geometry, final_start, real_targets, level=level, k_shear=k_shear,
                                  max_iter=max_iter, secondary=reference if final_surrogate_weight > 0 else None,
                                  secondary_weight=final_surrogate_weight or 1.0, tolerance_deg=tolerance_deg,
                                  **(real_fit_kw or {}))
        cal = _replace(rf.charset, name="calibrated", alternatives={})
        k_fac = float(cal.facet.stiffness)
        for kind_l in cal.ligaments:
            law = cal.ligaments[kind_l]
            fitted[kind_l] = (law.a, law.b, law.c, law.d)
        info["real_fit"] = rf.parameters
        info["real_fit_targets"] = rf.targets
        steps.append(_real_fit_step(rf, max(int(st["step"]) for st in steps) + 1, "real_targets", real_targets))
    surf_rows = []
    for side, _, s in facet_surfaces(geometry.levels[level]):
        p30, p03, p20, p02, p00 = s.coef
        # Eq. 4 in mm: f_mm = p30*1e-6 x_mm^3 + p03*1e-6 y^3 + p20*1e-3 x^2 + p02*1e-3 y^2 + p00*1e3
        for name, v, unit in (("p30", p30 * 1e-6, "1/mm^2"), ("p03", p03 * 1e-6, "1/mm^2"),
                              ("p20", p20 * 1e-3, "1/mm"), ("p02", p02 * 1e-3, "1/mm"), ("p00", p00 * 1e3, "mm")):
            surf_rows.append({"parameter": name, "side": side, "value": float(v), "unit": unit,
                              "rms_landmark_mm": s.rms_m * 1e3})
    return CalibrationResult(
        charset=cal, disc=dict(cal.disc.torque), facet_stiffness=k_fac, ligaments=fitted,
        summary=pd.DataFrame(steps), rom_fit=pd.concat(rom_fit, ignore_index=True),
        disc_points=pd.DataFrame(disc_pts), ligament_points=pd.DataFrame(lig_pts),
        facet_surfaces=pd.DataFrame(surf_rows), data_kind=data_kind,
        wall_time_s=time.perf_counter() - t0, info=info)


# ------------------------------------------------------------------ output
def write_characteristics(result: CalibrationResult, src_dir, out_dir, reference_source: str = "") -> Path:
    """Copy ``src_dir`` (data/characteristics) to ``out_dir`` with the calibrated rows replaced.

    disc.csv torque rows and facet.csv stiffness (shared by all sets in that directory) and the
    ``calibrated`` rows of ligaments_softplus.csv get kind ``calibrated_on_<data kind>``; the paper's
    'SSL neg.' alternative row is dropped (it belongs to the paper's calibration, not this one).
    ``load_characteristic_set("calibrated", data_dir=out_dir)`` loads the result.
    """
    src, out = Path(src_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kind = "calibrated_on_measured" if result.data_kind == "measured" else "calibrated_on_surrogate"
    # provenance text written into the result tables: names the function that made them
    src_note = f"lumbar.experiments.calibration.calibrate on {reference_source or 'the stepwise-reduction reference table'}"
    for f in sorted(src.glob("*.csv")):
        if f.name not in ("disc.csv", "facet.csv", "ligaments_softplus.csv"):
            shutil.copyfile(f, out / f.name)
    disc = pd.read_csv(src / "disc.csv", dtype=str, keep_default_na=False)
    for i, r in disc.iterrows():
        if r["parameter"] in ("torque_p1", "torque_p2", "torque_p3") and r["direction"] in result.disc:
            k = int(r["parameter"][-1]) - 1
            disc.loc[i, "value"] = repr(float(result.disc[r["direction"]][k]))
            disc.loc[i, ["kind", "source"]] = [kind, src_note]
            disc.loc[i, "note"] = f"Eq. 3 fitted (trf) to T(ROM_mean) = M on stage {DISC_STAGE}" + (
                "; p1 and p3 then scaled by the admissible fit (disc_torque posterior, results/calibration/"
                "posterior.csv)" if result.info.get("final_fit") is not None and
                result.info["final_fit"].posterior is not None else "")
    ks = getattr(result.charset.disc, "k_shear", None)
    if ks is not None and "real_fit" in result.info:
        disc = disc[disc["parameter"] != "shear_stiffness"]
        disc = pd.concat([disc, pd.DataFrame([{
            "parameter": "shear_stiffness", "direction": "shear", "value": repr(float(ks)), "unit": "N/m", "kind": kind,
            "source": src_note, "note": "fitted within the sourced range shear_stiffness_min..max on the real "
                                        "target rows (lumbar.experiments.calibration.fit_real_targets)"}])], ignore_index=True)
    write_table_atomic(disc, out / "disc.csv")
    fac = pd.read_csv(src / "facet.csv", dtype=str, keep_default_na=False)
    for i, r in fac.iterrows():
        if r["parameter"] == "stiffness":
            fac.loc[i, ["value", "unit", "kind", "source"]] = [repr(float(result.facet_stiffness)), "N/m", kind, src_note]
            fac.loc[i, "note"] = f"1-parameter fit on stage {FACET_STAGE} (facets removed with the vertebral arch)"
    write_table_atomic(fac, out / "facet.csv")
    sp = pd.read_csv(src / "ligaments_softplus.csv", dtype=str, keep_default_na=False)
    sp = sp[sp["set"] != "calibrated"]
    new = []
    for kind_l, law in result.charset.ligaments.items():
        if not hasattr(law, "a"):
            continue
        on_elongation = law.law_length_m is not None
        note = ("Eq. 7 on elongation in percent of law_length (calibrated with lumbar.experiments.calibration."
                "fit_admissible: force scale and pre-elongation of the prior law, real targets and admissibility)"
                if on_elongation else
                f"Eq. 7 (a,b,d fitted, c = -a*ln(1+exp(b/d)) so F(0)=0) on stage {LIGAMENT_STAGE.get(kind_l, '?')}; "
                "no ITL row (ITL absent, as Table 3)")
        values = [(p, v, {"a": "N", "b": "%", "c": "N", "d": "%"}[p])
                  for p, v in zip("abcd", (law.a, law.b, law.c, law.d))]
        if on_elongation:
            values += [("law_length", law.law_length_m * 1e3, "mm"), ("prestrain", law.prestrain_pct, "%")]
        for p, v, unit in values:
            new.append({"set": "calibrated", "ligament": kind_l, "variant": "primary", "parameter": p,
                        "value": repr(float(v)), "unit": unit, "kind": kind, "source": src_note, "note": note})
    write_table_atomic(pd.concat([pd.DataFrame(new), sp], ignore_index=True), out / "ligaments_softplus.csv")
    return out


def _fit_not_converged(result: CalibrationResult, structure: str) -> int:
    """Scenarios of the calibration step fitting ``structure`` that had no equilibrium at the fitted values:
    a table value fitted on them is marked (column ``fit_not_converged`` > 0) instead of looking clean."""
    s = result.summary
    if s is None or "structure" not in getattr(s, "columns", ()):
        return 0
    sel = s[s["structure"] == structure]
    return int(pd.to_numeric(sel["n_not_converged"], errors="coerce").fillna(0).sum())


def table1(result: CalibrationResult, paper) -> pd.DataFrame:
    rows = []
    for d in MAIN_DIRECTIONS:
        p, q = result.disc[d], paper.disc.torque[d]
        rows.append({"direction": d, "p1_nm": p[0], "p2_rad3": p[1], "p3_nm_per_rad": p[2],
                     "paper_p1_nm": q[0], "paper_p2_rad3": q[1], "paper_p3_nm_per_rad": q[2],
                     "fit_stage": DISC_STAGE, "fit_not_converged": _fit_not_converged(result, f"disc:{d}"),
                     "data_kind": result.data_kind})
    return pd.DataFrame(rows)


def table2(result: CalibrationResult, paper) -> pd.DataFrame:
    rows = []
    fs = result.facet_surfaces
    for p in ("p30", "p03", "p20", "p02", "p00"):
        r = {"parameter": p}
        for side in ("left", "right"):
            sel = fs[(fs["parameter"] == p) & (fs["side"] == side)]
            r[f"{side}"] = float(sel["value"].iloc[0]) if len(sel) else np.nan
            r["unit"] = sel["unit"].iloc[0] if len(sel) else ""
            r[f"paper_{side}"] = paper.facet.surface_paper.get(side, {}).get(p, np.nan)
        r["note"] = ("project geometry, fitted local frame (u ~ superior, w = joint normal), mm; paper's "
                     "values are in the paper's own frame (comparison only)")
        r["data_kind"] = "geometry"
        rows.append(r)
    rows.append({"parameter": "stiffness", "left": result.facet_stiffness, "right": result.facet_stiffness,
                 "unit": "N/m", "paper_left": paper.facet.stiffness, "paper_right": paper.facet.stiffness,
                 "note": f"Eq. 5 c_stiff fitted on stage {FACET_STAGE}", "data_kind": result.data_kind})
    return pd.DataFrame(rows)


def table3(result: CalibrationResult, paper) -> pd.DataFrame:
    """Table 3 analog: the calibrated Eq. 7 laws beside the paper's. For laws on elongation also the law length
    [mm] (the length their percent strain refers to), the pre-elongation at the reference geometry [mm], the force
    scale relative to the calibration's prior law and the prior's source."""
    rows = []
    prior = result.info.get("prior_set")
    for k, law in result.charset.ligaments.items():
        if not hasattr(law, "a"):
            continue
        q = paper.ligaments.get(k)
        pr = prior.ligaments.get(k) if prior is not None else None
        rows.append({"ligament": k, "a_n": law.a, "b_pct": law.b, "c_n": law.c, "d_pct": law.d,
                     "prestrain_pct": law.prestrain_pct,
                     "law_length_mm": law.law_length_m * 1e3 if law.law_length_m is not None else np.nan,
                     "pre_elongation_mm": law.pre_elongation_m * 1e3 if law.law_length_m is not None else np.nan,
                     "force_scale_vs_prior": law.a / pr.a if pr is not None and pr.a else np.nan,
                     "prior": PRIOR_SOURCE.get(k, ("", ""))[1] if pr is not None else "",
                     "fit_stage": LIGAMENT_STAGE.get(k, "real targets + admissibility"),
                     "paper_a_n": getattr(q, "a", np.nan), "paper_b_pct": getattr(q, "b", np.nan),
                     "paper_c_n": getattr(q, "c", np.nan), "paper_d_pct": getattr(q, "d", np.nan),
                     "fit_not_converged": _fit_not_converged(result, k), "data_kind": result.data_kind})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ derived disc-only rows
def invert_eq3(p, moment_nm):
    """Smallest phi >= 0 [rad] with Eq. 3 T(phi) = moment (before any torque peak); NaN if none."""

    grid = np.linspace(0.0, math.radians(60.0), 60001)
    T = eq3(grid, p)
    above = np.flatnonzero(T >= moment_nm)
    if above.size == 0:
        return float("nan")
    j = above[0]
    if j == 0:
        return 0.0
    return brentq(lambda x: eq3(x, p) - moment_nm, grid[j - 1], grid[j], xtol=1e-14)


def derived_disc_only_rows(torque: dict, moments_nm=(1.0, 2.5, 5.0, 7.5, 10.0), source="", note="") -> pd.DataFrame:
    rows = []
    for d in MAIN_DIRECTIONS:
        for M in moments_nm:
            rows.append({"stage": DISC_STAGE, "direction": d, "moment_nm": float(M),
                         "rom_mean_deg": round(math.degrees(invert_eq3(torque[d], M)), 4),
                         "rom_min_deg": np.nan, "rom_max_deg": np.nan, "n_specimens": 8,
                         "kind": "derived_from_published_fit", "source": source, "note": note})
    return pd.DataFrame(rows)



# ------------------------------------------------------------------ figures (matplotlib object API, no pyplot)
def plot_disc_torque_angle(disc_points: pd.DataFrame, table: pd.DataFrame, path, data_label="") -> None:
    """Fig. 4 analog: disc torque vs angle [deg], data points (ROM_mean, M) and the fitted Eq. 3."""
    fig, ax = subplots(figsize=(7, 4.5))
    colours = dict(zip(MAIN_DIRECTIONS, ("C0", "C1", "C2", "C3")))
    for d in MAIN_DIRECTIONS:
        pts = disc_points[disc_points["direction"] == d]
        row = table[table["direction"] == d].iloc[0]
        p = (row["p1_nm"], row["p2_rad3"], row["p3_nm_per_rad"])
        phi = np.linspace(0, max(16.0, pts["rom_deg"].max() * 1.15), 300)
        ax.plot(phi, eq3(np.radians(phi), p), "-", color=colours[d], label=f"{d} (Eq. 3 fit)")
        ax.plot(pts["rom_deg"], pts["moment_nm"], "o--", color=colours[d], mfc="none", lw=0.8)
    ax.set_xlabel("rotation angle [deg]")
    ax.set_ylabel("disc torque [N*m]")
    ax.set_title("Disc torque-angle (stage w/o ALL)" + (f" - data: {data_label}" if data_label else ""), fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=120)


def plot_ligament_characteristics(points: pd.DataFrame, table: pd.DataFrame, path, data_label="") -> None:
    """Fig. 5 analog: per ligament, modelled (strain, force) at the fit stage's solutions and the fitted Eq. 7."""
    fig, axes = subplots(2, 3, figsize=(11, 6.5))
    for ax, k in zip(axes.ravel(), ("ALL", "PLL", "CL", "FL", "ISL", "SSL")):
        row = table[table["ligament"] == k].iloc[0]
        pts = points[points["ligament"] == k] if len(points) else points
        lo = min(-5.0, pts["strain_pct"].min() - 2) if len(pts) else -5.0
        hi = max(25.0, pts["strain_pct"].max() + 2) if len(pts) else 25.0
        eps = np.linspace(lo, hi, 300)
        F, _ = softplus_force(eps, row["a_n"], row["b_pct"], row["c_n"], row["d_pct"])
        ax.plot(eps, F, "-", color="C0", label="Eq. 7 fit (tension-only)")
        for g, gp in pts.groupby("group") if len(pts) else []:
            gp = gp.sort_values("strain_pct")
            ax.plot(gp["strain_pct"], gp["force_n"], "o--", mfc="none", lw=0.6, label=f"{g} (model)")
        ax.set_title(f"{k} (fit on {row['fit_stage']})", fontsize=9)
        ax.set_xlabel("strain [%]")
        ax.set_ylabel("force [N]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    if data_label:
        fig.suptitle(f"Ligament characteristics calibrated on {data_label}", fontsize=10)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)


# ------------------------------------------------------------------ fit on real targets
#: parameters of the real-target fit: log10 scale factors of the facet contact stiffness, the disc shear
#: stiffness and the force of each ligament law (the law's shape, knee and prestrain are kept)
REAL_FIT_PARAMETERS = ("facet_stiffness", "disc_shear", "ALL", "PLL", "FL", "CL", "ISL", "SSL")
#: bounds of the log10 scales (decades) relative to the start set; the disc shear stiffness is instead
#: bounded by its sourced range (data/characteristics/disc.csv shear_stiffness_min/max)
FACET_STIFFNESS_RANGE = (1.0e3, 9.9e6)   # N/m, absolute bounds of the facet stiffness in the real-target fit
REAL_FIT_LOG10_BOUNDS = {"ALL": (-3.0, 1.0), "PLL": (-3.0, 1.0),
                         "FL": (-3.0, 1.0), "CL": (-3.0, 1.0), "ISL": (-3.0, 1.0), "SSL": (-3.0, 1.0)}
AT_BOUND_FRACTION = 0.01          # a parameter within 1 % of its bound range from a bound is flagged at_bound
IDENTIFIABLE_MIN_DEG = 0.05       # ROM change [deg] per decade below which a parameter is not identifiable


@dataclass
class RealFit:
    """Result of :func:`fit_real_targets`: the fitted set and one row per parameter."""

    charset: object
    parameters: pd.DataFrame     # parameter, start, value, unit, log10_scale, lower, upper, at_bound, identifiable,
                                 # sensitivity_deg_per_decade
    targets: pd.DataFrame        # stage, direction, moment_nm, rom_mean_deg, rom_sim_deg, rel_error, converged
    cost: float
    n_evaluations: int


def _scale_charset(cs, names, scales, k_shear):
    """``cs`` with ligament forces (softplus a and c; Rupp forces) and the facet stiffness scaled."""
    ligs = dict(cs.ligaments)
    for name, s in zip(names, scales):
        if name in ligs:
            law = ligs[name]
            if hasattr(law, "a"):
                ligs[name] = _replace(law, a=law.a * s, c=law.c * s)
            else:
                ligs[name] = _replace(law, f_a_n=law.f_a_n * s, f_b_n=law.f_b_n * s)
    facet = cs.facet
    if "facet_stiffness" in names:
        facet = _replace(facet, stiffness=float(facet.stiffness * scales[list(names).index("facet_stiffness")]))
    disc = _replace(cs.disc, k_shear=float(k_shear)) if k_shear is not None else cs.disc
    return _replace(cs, ligaments=ligs, facet=facet, disc=disc)


def fit_real_targets(geometry, charset, targets: pd.DataFrame, level="L4-L5", parameters=REAL_FIT_PARAMETERS,
                     k_shear=None, reg_weight=0.02, max_iter=50, tol=1e-7, max_nfev=80,
                     secondary: pd.DataFrame | None = None, secondary_weight=0.3, tolerance_deg=0.5) -> RealFit:
    """Fit force scales of the passive structures so that the unit matches measured ROM rows.

    ``targets``: rows (stage, direction, moment_nm, rom_mean_deg) of real data (e.g. the intact L4-L5 ROM
    at 10 N*m of Yamamoto et al. 1989). Residual: relative ROM error (sim - measured) / measured per row,
    plus ``reg_weight`` times each log10 scale (a weak pull towards the start set, so that directions the
    data do not constrain stay at the start values). Parameters (``REAL_FIT_PARAMETERS``): log10 scale
    factors of the facet stiffness and of each ligament's force; ``disc_shear`` is fitted within the
    sourced range ``charset.disc.k_shear_range`` (N/m). Before the fit, parameters whose ROM sensitivity is
    below ``IDENTIFIABLE_MIN_DEG`` per decade in every target row (e.g. a ligament that stays slack) are
    not fitted: they keep the start value and are listed with ``identifiable = False``. After the fit,
    ``at_bound`` flags parameters within ``AT_BOUND_FRACTION`` of a bound.
    """
    t = targets.reset_index(drop=True)
    if t.empty:
        raise ValueError("fit_real_targets: no target rows")
    measured = t["rom_mean_deg"].to_numpy(float)
    if not np.all(np.isfinite(measured) & (measured > 0)):
        raise ValueError("fit_real_targets: every target rom_mean_deg must be finite and > 0 deg")
    n_real = len(t)
    # residual scales: real rows in units of 25 % of the measured value (the acceptance band of
    # lumbar.experiments.validation), secondary rows in units of their range (rows without a range: 2 x tolerance_deg)
    scale = 0.25 * measured / 1.0
    keys = ["stage", "direction", "moment_nm"]
    if secondary is not None and len(secondary):
        sec = secondary.reset_index(drop=True)
        sec = sec[~sec[keys].apply(tuple, axis=1).isin(set(t[keys].apply(tuple, axis=1)))].reset_index(drop=True)
        # weights: the secondary rows TOGETHER count secondary_weight times as much as the real rows together
        # (so 100 surrogate rows cannot outvote 4 measured ones)
        sw = _widths(sec, tolerance_deg) / math.sqrt(float(secondary_weight) * n_real / max(len(sec), 1))
        t_all = pd.concat([t[keys + ["rom_mean_deg"]], sec[keys + ["rom_mean_deg"]]], ignore_index=True)
        measured_all = t_all["rom_mean_deg"].to_numpy(float)
        scale = np.concatenate([scale, sw])
    else:
        t_all, measured_all = t, measured
    ks0 = float(k_shear if k_shear is not None else charset.disc.k_shear)
    names, lo, hi, x0 = [], [], [], []
    for p in parameters:
        if p == "disc_shear":
            rng = charset.disc.k_shear_range
            if rng is None:
                continue
            names.append(p)
            lo.append(math.log10(rng[0]))
            hi.append(math.log10(rng[1]))
            x0.append(float(np.clip(math.log10(ks0), lo[-1], hi[-1])))
        elif p == "facet_stiffness":
            names.append(p)
            k_start = float(charset.facet.stiffness)
            lo.append(math.log10(FACET_STIFFNESS_RANGE[0] / k_start))
            hi.append(math.log10(FACET_STIFFNESS_RANGE[1] / k_start))
            x0.append(float(np.clip(0.0, lo[-1], hi[-1])))
        elif p in charset.ligaments:
            names.append(p)
            b = REAL_FIT_LOG10_BOUNDS[p]
            lo.append(b[0])
            hi.append(b[1])
            x0.append(0.0)
    lo, hi, x0 = np.array(lo), np.array(hi), np.array(x0)
    fsu = build_fsu(geometry, charset, level, k_shear=ks0)
    m = fsu.model
    par_scale0, k0 = m.f_scale.copy(), m.k_stiff.copy()
    groups = {k: np.isin(m.f_group, _kind_groups(m, k)) for k in names}
    ss = StageSolver(fsu, t_all[["stage", "direction", "moment_nm"]], max_iter=max_iter, tol=tol)
    n_eval = [0]

    def apply(q):
        m.f_scale[:] = par_scale0
        m.k_stiff[:] = k0
        for name, v in zip(names, q):
            if name == "facet_stiffness":
                m.k_stiff[:] = k0 * 10.0 ** v
            elif name == "disc_shear":
                for d in m.discs:
                    d.k_shear = 10.0 ** v
            else:
                m.f_scale[groups[name]] = par_scale0[groups[name]] * 10.0 ** v

    def rom(q):
        apply(q)
        n_eval[0] += 1
        r, conv, _ = ss.run()
        return r, conv

    r0, c0 = rom(x0)
    sens = np.zeros(len(names))
    for j in range(len(names)):
        dq = x0.copy()
        step = 0.1 if dq[j] + 0.1 <= hi[j] else -0.1
        dq[j] += step
        r1, c1 = rom(dq)
        ok = c0 & c1
        sens[j] = float(np.max(np.abs((r1 - r0)[ok]) / abs(step))) if ok.any() else 0.0
    free = sens >= IDENTIFIABLE_MIN_DEG

    def residual(qf):
        q = x0.copy()
        q[free] = qf
        r, conv = rom(q)
        return np.concatenate([np.where(conv, (r - measured_all) / scale, PENALTY), reg_weight * (q - x0)[free]])

    q = x0.copy()
    if free.any():
        sol = least_squares(residual, x0[free], method="trf", bounds=(lo[free], hi[free]), x_scale=0.3,
                            diff_step=1e-3, xtol=1e-8, ftol=1e-8, gtol=1e-8, max_nfev=max_nfev)
        q[free] = sol.x
    r, conv = rom(q)
    r, conv = r[:n_real], conv[:n_real]
    width = hi - lo
    at_bound = free & ((q - lo <= AT_BOUND_FRACTION * width) | (hi - q <= AT_BOUND_FRACTION * width))
    scales = 10.0 ** q
    lig_names = [n for n in names if n not in ("disc_shear",)]
    lig_scales = [10.0 ** q[names.index(n)] for n in lig_names]
    ks = 10.0 ** q[names.index("disc_shear")] if "disc_shear" in names else ks0
    cs = _scale_charset(charset, lig_names, lig_scales, ks)
    rows = []
    for j, n in enumerate(names):
        if n == "disc_shear":
            start, value, unit = 10.0 ** x0[j], float(ks), "N/m"
        elif n == "facet_stiffness":
            start, value, unit = float(charset.facet.stiffness) * 10.0 ** x0[j], float(cs.facet.stiffness), "N/m"
        else:
            start, value, unit = 1.0, float(scales[j]), "force scale (-)"
        rows.append({"parameter": n, "start": start, "value": value, "unit": unit,
                     "log10_change": float(q[j] - x0[j]),
                     "lower": float(10.0 ** lo[j] * (1.0 if n == "disc_shear" else charset.facet.stiffness)
                                    if n in ("disc_shear", "facet_stiffness") else 10.0 ** lo[j]),
                     "upper": float(10.0 ** hi[j] * (1.0 if n == "disc_shear" else charset.facet.stiffness)
                                    if n in ("disc_shear", "facet_stiffness") else 10.0 ** hi[j]),
                     "bound_unit": "N/m" if n in ("disc_shear", "facet_stiffness") else "force scale (-)",
                     "sensitivity_deg_per_decade": float(sens[j]), "identifiable": bool(free[j]),
                     "at_bound": bool(at_bound[j])})
    tt = t[["stage", "direction", "moment_nm", "rom_mean_deg"]].copy()
    tt["rom_sim_deg"] = r
    tt["rel_error"] = (r - measured) / measured
    tt["converged"] = conv
    for row in rows:
        if row["at_bound"]:
            log.info("real-target fit: %s ends at its bound (%.4g %s)", row["parameter"], row["value"], row["unit"])
        if not row["identifiable"]:
            log.info("real-target fit: %s not identifiable from these rows (%.3g deg per decade): kept at %.4g",
                     row["parameter"], row["sensitivity_deg_per_decade"], row["start"])
    return RealFit(cs, pd.DataFrame(rows), tt, float(np.sum(tt["rel_error"] ** 2)), n_eval[0])


# ------------------------------------------------------------------ ligament laws on elongation: the prior set
#: the law each calibrated ligament starts from (its prior), on elongation in percent of the paper's own fibre:
#: paper 1 Table 3, except the FL (Table 3's law is concave: its force falls with stretch, which the paper attributes
#: to the vertebral-arch artefact, Sect. 4.2) and the ITL (no Table 3 row: the paper's model has an ITL with a
#: "non-validated characteristic", Sects. 2.2.4 and 4.3): for both the prior is the paper's elongation-based
#: characteristic, the Rupp et al. 2015 law of Appendix 1, refitted with Eq. 7
PRIOR_SOURCE = {"ALL": ("calibrated", "Table 3"), "PLL": ("calibrated", "Table 3"), "CL": ("calibrated", "Table 3"),
                "ISL": ("calibrated", "Table 3"), "SSL": ("calibrated", "Table 3"),
                "FL": ("rupp2015", "Appendix 1 Rupp et al. 2015 law, refitted with Eq. 7 (F(0) = 0)"),
                "ITL": ("rupp2015", "Appendix 1 Rupp et al. 2015 law, refitted with Eq. 7 (F(0) = 0)")}
ELONGATION_LIGAMENTS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL")


def paper_fibre_slack_length(kind, prestrain_pct, data_dir=None) -> float:
    """The paper model's slack length [m] of a ligament kind at the paper's prestrain: the mean in-situ length of its
    strands, l_set = l_lig,0 * (1 + eps_Rupp) (Appendix 1, calculated shape parameters and Rupp inputs), divided
    by (1 + prestrain). The length on which the paper's percent strains are defined (derived_from_published_fit)."""
    sc = load_shape_check(data_dir)
    rupp = load_characteristic_set("rupp2015", data_dir=data_dir).ligaments
    sel = sc[sc["ligament"] == kind]
    if sel.empty or kind not in rupp:
        raise ValueError(f"no Appendix 1 fibre lengths for ligament {kind!r} (rupp2015_shape_check.csv)")
    l_set = float(sel["l0"].mean()) * (1.0 + rupp[kind].prestrain)
    return l_set / (1.0 + prestrain_pct / 100.0)


def rupp_as_softplus(law, law_length_m, max_elongation_m=5e-3, n=201):
    """Eq. 7 (a, b, c, d) with F(0) = 0, d > 0, least-squares fitted on elongation 0..``max_elongation_m`` in percent of
    ``law_length_m`` to a Rupp et al. (2015) law of the whole ligament (toe F_A (dl/l_A)^nu, linear beyond)."""
    e = np.linspace(0.0, max_elongation_m, n)
    K = (law.f_b_n - law.f_a_n) / (law.l_b_m - law.l_a_m)
    nu = law.l_a_m * K / law.f_a_n
    F = np.where(e < law.l_a_m, law.f_a_n * (np.clip(e, 0, None) / law.l_a_m) ** nu, law.f_a_n + K * (e - law.l_a_m))
    eps = 100.0 * e / law_length_m
    sol = least_squares(lambda q: softplus_zero_law(eps, q[0], q[1], q[2]) - F, [50.0, -10.0, 3.0],
                        bounds=([0.01, -60.0, 0.05], [5000.0, 40.0, 50.0]), xtol=1e-12, ftol=1e-12)
    a, b, d = (float(v) for v in sol.x)
    return a, b, c_zero(a, b, d), d, float(np.abs(sol.fun).max())


def elongation_prior(published=None, data_dir=None):
    """The calibration's prior: every ligament kind of :data:`ELONGATION_LIGAMENTS` with the law of
    :data:`PRIOR_SOURCE` defined on elongation (``SoftplusLaw.law_length_m`` = the paper's fibre slack length,
    :func:`paper_fibre_slack_length`) at the paper's prestrain (Sect. 2.2.4). Returns (CharacteristicSet named
    "calibrated", provenance table: ligament, a, b, c, d, prestrain_pct, law_length_mm, source, note)."""
    pub = published if published is not None else load_characteristic_set("calibrated", data_dir=data_dir)
    ligs, rows = {}, []
    for kind in ELONGATION_LIGAMENTS:
        set_name, what = PRIOR_SOURCE[kind]
        pre = pub.ligaments[kind].prestrain_pct if kind in pub.ligaments else \
            load_characteristic_set("shirazi_adl1986", data_dir=data_dir).ligaments[kind].prestrain_pct
        L = paper_fibre_slack_length(kind, pre, data_dir)
        note = ""
        if set_name == "calibrated":
            src = pub.ligaments[kind]
            a, b, c, d = src.a, src.b, src.c, src.d
        elif set_name == "rupp2015":
            a, b, c, d, err = rupp_as_softplus(load_characteristic_set("rupp2015", data_dir=data_dir).ligaments[kind], L)
            note = f"Eq. 7 fit to the Rupp law over 0-5 mm elongation, largest deviation {err:.2g} N"
        else:
            src = load_characteristic_set(set_name, data_dir=data_dir).ligaments[kind]
            a, b, c, d = src.a, src.b, src.c, src.d
        ligs[kind] = SoftplusLaw(a, b, c, d, pre, source=f"prior: paper 1 {what} on elongation", law_length_m=L)
        rows.append({"ligament": kind, "a_n": a, "b_pct": b, "c_n": c, "d_pct": d, "prestrain_pct": pre,
                     "law_length_mm": L * 1e3, "pre_elongation_mm": pre / 100.0 * L * 1e3,
                     "source": f"paper 1 {what}", "note": note})
    cs = dataclasses.replace(pub, name="calibrated", ligaments=ligs, absent={}, alternatives={},
                             source="elongation prior (lumbar.experiments.calibration.elongation_prior)")
    return cs, pd.DataFrame(rows)


def calibration_prior(published=None, geometry=None, level="L4-L5", geometry_path=None, prior="remus2021",
                      data_dir=None):
    """The admissible fit's prior: (prior characteristic set on elongation, provenance table, {fit parameter: prior
    spread in fit units}).

    ``prior``: "remus2021" (default): every ligament law is the Remus et al. (2021) law of the same fibres
    (:func:`lumbar.experiments.priors.remus_prior`; needs the Visible Human folder ``geometry_path`` with its
    ``*_UWMat.lig`` files); "table3": paper 1 Table 3 on elongation (:func:`elongation_prior`). The ligament spreads
    are how much the two sources disagree on this level's fibres, per kind (:func:`priors.ligament_spreads`); without
    the Remus files (another geometry) the prior is Table 3 with the default spreads, and the provenance says so."""
    from ..geometry.visible_human import read_uw_materials  # noqa: PLC0415 - only with a Visible Human folder
    from . import priors as PR  # noqa: PLC0415 - calibration-only helper module

    if prior not in PR.PRIORS:
        raise ValueError(f"ligament prior {prior!r}; expected one of {PR.PRIORS}")
    table3, prov = elongation_prior(published, data_dir)
    if geometry_path is None or geometry is None or level not in getattr(geometry, "levels", {}):
        prov = prov.assign(spread_source="default spreads (no Remus et al. 2021 laws for this geometry)")
        return table3, prov, {}
    remus, rprov = PR.remus_prior(table3, geometry.levels[level], read_uw_materials(geometry_path, level),
                                  ELONGATION_LIGAMENTS)
    spreads = PR.ligament_spreads(PR.source_disagreement(remus.ligaments, table3.ligaments))
    chosen, cprov = (remus, rprov) if prior == "remus2021" else (table3, prov)
    cprov = cprov.assign(scale_spread_log10=[spreads.get(f"{k}:scale") for k in cprov["ligament"]],
                         pre_elongation_spread_mm=[spreads.get(f"{k}:pre_elongation") for k in cprov["ligament"]],
                         prior=prior)
    return chosen, cprov, spreads


def read_prior_set(path, published):
    """The prior characteristic set the calibration used, rebuilt from its provenance table
    (results/calibration/calibration_prior.csv: ligament, a_n, b_pct, c_n, d_pct, prestrain_pct, law_length_mm) on
    ``published`` (disc and facet): the one record of the prior, read by the admissibility and the other levels (the
    force-scale criterion is relative to it)."""
    df = pd.read_csv(path)
    need = {"ligament", "a_n", "b_pct", "c_n", "d_pct", "prestrain_pct", "law_length_mm"}
    if not need <= set(df.columns):
        raise ValueError(f"{path}: the prior table needs the columns {sorted(need)}; has {sorted(df.columns)}")
    ligs = dict(published.ligaments)
    for r in df.itertuples():
        ligs[r.ligament] = SoftplusLaw(float(r.a_n), float(r.b_pct), float(r.c_n), float(r.d_pct),
                                       float(r.prestrain_pct), source=f"prior ({path})",
                                       law_length_m=float(r.law_length_mm) * 1e-3)
    return dataclasses.replace(published, name="calibrated", ligaments=ligs, absent={}, alternatives={},
                               source=f"calibration prior ({path})")


# ------------------------------------------------------------------ the admissible fit
#: moments [N*m] of the fit's probe (the admissibility check itself uses 0.25 N*m steps); 0.25 N*m watches the
#: compliance at the neutral position (the snap-through criterion's first step), 1 N*m gives the neutral-zone proxy
PROBE_MOMENTS = (0.25, 1.0, 2.0, 3.0, 5.0, 7.5, 10.0)
#: the compliance of the probe's [2, 3] N*m window is the reference of the "no compliance rise" penalty (the
#: criterion takes the tangent at 2.5 N*m); later windows may not exceed it by more than FIT_MARGIN["compliance_rise"]
COMPLIANCE_REFERENCE_WINDOW = (2.0, 3.0)
PROBE_DIRECTIONS = ("flexion", "extension", "lateral_bending_right", "lateral_bending_left",
                    "axial_rotation_left", "axial_rotation_right")
#: margins of the fit's penalties inside the admissibility limits (so that the 0.25 N*m check passes with room)
FIT_MARGIN = {"rest_facet_n": 15.0, "pretension_fraction": 0.9, "nz_fraction": 0.8, "compression_share": 0.2,
              "functional_n": 2.0, "isl_ssl_share": 0.12, "compliance_rise": 0.05, "first_step_deg": 0.4,
              "rom_rel": 0.2, "disc_compression_mm": 0.01, "remus_factor": 1.25,
              "scale_factor": 1.1}
PENALTY_WEIGHT = 3.0
#: spread of a real ROM row when its source gives none (Yamamoto et al. 1989's abstract gives means only): 25 % of the
#: measured value, the validation's acceptance band (an assumption, stated in results/calibration/posterior.csv)
DATA_SD_REL = 0.25
#: bounds of the disc torque-law scales (p1 and p3 of Eq. 3 of one direction scaled together) of the admissible fit;
#: their prior is the disc-only fit (step 1) with the spread of a measured row (DATA_SD_REL)
DISC_TORQUE_SCALE_BOUNDS = (0.25, 4.0)
#: a fitted pre-elongation may leave a ligament slack by this much [mm] at rest ...
PRE_ELONGATION_SLACK_MM = 1.5
#: ... or stretch it by at most this prestrain [% of its law length]: 2.5 x the paper's largest prestrain (10 %,
#: Sect. 2.2.4); a larger one would make the shortest fibres of other levels (capsules of about 1.2 mm) unusable
MAX_PRESTRAIN_PCT = 25.0
#: bounds of the fitted force scales: wider than the admissible 0.1-10 x the source law (a scale outside it must be
#: explained by the Remus et al. 2021 model of these fibres, lumbar.experiments.admissibility.remus_comparison)
FIT_SCALE_BOUNDS = (0.02, 10.0)
#: common ligament force scales tried for the start of :func:`fit_admissible` when no start is given
START_SCALES = (0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 1.0)


class _Probe:
    """Rest state, pure moments at PROBE_MOMENTS in PROBE_DIRECTIONS and a 1000 N follower load of a unit (built with
    ``follower=True``), solved in one batch warm-started from the last converged states.

    :meth:`linearised` returns the states after one Newton step from the last equilibrium under changed parameters:
    the first-order change of every state with a parameter (implicit function theorem), which makes the fit's
    finite-difference Jacobian cost one residual evaluation per parameter instead of one equilibrium solve."""

    def __init__(self, fsu, max_iter=50, tol=1e-8):
        self.fsu, m = fsu, fsu.model
        self.scen = [("rest", "", 0.0)] + [("moment", d, M) for M in PROBE_MOMENTS for d in PROBE_DIRECTIONS] + \
                    [("compression", "", 1000.0)]
        B = len(self.scen)
        self.loads = np.zeros((B, m.nb, 6))
        self.fm = np.repeat(fsu.masks(["intact"])[0], B, axis=0)
        cab = m.f_group == fsu.follower_group
        for i, (kind, d, M) in enumerate(self.scen):
            if kind == "moment":
                self.loads[i] = moment_loads([d], [M], m.nb)[0]
            elif kind == "compression":
                self.fm[i, cab] = M
        self.cm = np.ones((B, m.nc))
        self.kw = dict(max_iter=max_iter, tol_force=tol, tol_moment=tol)
        self.st = level_structures(m, fsu.level.name, dict(enumerate(fsu.surface_side)))
        self.sel = [0, self.scen.index(("moment", "flexion", PROBE_MOMENTS[-1])), B - 1]
        # what metrics() reads, fixed per probe: the moment scenarios (row, axis, sign), the fibre groups of each
        # ligament kind and each structure's fibre mask
        self.rot_rows = [i for i, sc in enumerate(self.scen) if sc[0] == "moment"]
        self.rot_axis = np.array([AXIS_OF[self.scen[i][1]][0] for i in self.rot_rows])
        self.rot_sign = np.array([AXIS_OF[self.scen[i][1]][1] for i in self.rot_rows], float)
        self.kinds = {}
        for g, (_, k, _lv) in enumerate(m.fibre_groups):
            self.kinds.setdefault(k, []).append(g)
        self.group_masks = {k: np.isin(m.f_group, g) for k, g in self.st.groups.items()}
        self.remus = None          # kind -> [(fibre mask, Remus et al. 2021 material)] (:meth:`set_remus`)
        self.warm = None
        self.state = None
        self.n_solves = 0

    def set_remus(self, materials: dict):
        """Evaluate the Remus et al. (2021) law of every fibre group named in ``materials`` (``read_uw_materials`` of
        the level) at the 10 N*m flexion state too (metrics ``flex_remus``): the sourced exception of the force-scale
        criterion, compared inside the fit."""
        m = self.fsu.model
        self.remus = {}
        for g, (name, kind, lv) in enumerate(m.fibre_groups):
            if lv == self.fsu.level.name and name in materials:
                self.remus.setdefault(kind, []).append((m.f_group == g, materials[name]))

    def _remus_pairs(self, x, R):
        """{kind: (model tension, Remus et al. 2021 tension) [N]} at the state of the admissibility criterion's
        comparison (``ADM.REMUS_STATES``: rest and 10 N*m in four directions) where the Remus law carries the kind
        most; {} without :meth:`set_remus`."""
        if not self.remus:
            return {}
        m = self.fsu.model
        rows = [0] + [self.scen.index(("moment", d, M)) for _, d, M in ADM.REMUS_STATES if d]
        length, _, T = m.fibre_state(x[rows], R[rows], self.fm[rows])[:3]
        out = {}
        for k, parts in self.remus.items():
            t_r = sum(uw_force(length[:, mask], m.f_lref[mask], mat).sum(axis=1) for mask, mat in parts)
            t_m = sum(T[:, mask].sum(axis=1) for mask, _ in parts)
            j = int(np.argmax(t_r))
            out[k] = (float(t_m[j]), float(t_r[j]))
        return out

    def _cold(self):
        m = self.fsu.model
        i_comp = len(self.scen) - 1
        idx = {M: [i for i, s in enumerate(self.scen) if s[0] == "moment" and s[2] == M] for M in PROBE_MOMENTS}
        rest = solve(m, self.loads[[0]], fmask=self.fm[[0]], retry_load_steps=(4, 16), **self.kw)
        nd = len(PROBE_DIRECTIONS)
        path = np.stack([self.loads[idx[M]] for M in PROBE_MOMENTS])
        seq = solve_sequence(m, path, x0=np.repeat(rest.x, nd, 0), R0=np.repeat(rest.R, nd, 0),
                             fmask=self.fm[idx[PROBE_MOMENTS[0]]], **self.kw)
        comp = solve(m, self.loads[[i_comp]], x0=rest.x, R0=rest.R, fmask=self.fm[[i_comp]], load_steps=4, **self.kw)
        x = np.empty((len(self.scen), m.nb, 3))
        R = np.empty((len(self.scen), m.nb, 3, 3))
        x[0], R[0] = rest.x[0], rest.R[0]
        x[i_comp], R[i_comp] = comp.x[0], comp.R[0]
        for M, r in zip(PROBE_MOMENTS, seq):
            x[idx[M]], R[idx[M]] = r.x, r.R
        return x, R

    def run(self):
        """Equilibria at the model's current parameters; keeps them (and their stiffness) for :meth:`linearised`."""
        m = self.fsu.model
        if self.warm is None:
            self.warm = self._cold()
        res = solve(m, self.loads, x0=self.warm[0], R0=self.warm[1], fmask=self.fm, cmask=self.cm,
                    retry_load_steps=(), **self.kw)
        if not res.converged.all():      # fall back to the continuation from the reference state
            x, R = self._cold()
            res = solve(m, self.loads, x0=x, R0=R, fmask=self.fm, cmask=self.cm, retry_load_steps=(4,), **self.kw)
        self.n_solves += len(self.scen)
        if res.converged.all():
            self.warm = (res.x, res.R)
            _, J = m.evaluate(res.x, res.R, self.loads, self.fm, self.cm, jacobian=True)
            n = 6 * m.nb
            self.state = (res.x, res.R, J.reshape(-1, n, n))
        else:
            self.state = None
        return res.x, res.R, bool(res.converged.all())

    def linearised(self):
        """(x, R) one Newton step from the kept equilibria under the model's current parameters."""
        m = self.fsu.model
        x, R, J = self.state
        Q, _ = m.evaluate(x, R, self.loads, self.fm, self.cm, jacobian=False)
        d = np.linalg.solve(J, -Q.reshape(len(x), -1)[..., None])[..., 0].reshape(len(x), m.nb, 6)
        return x + d[..., :3], so3.exp(d[..., 3:]) @ R

    def metrics(self, x, R):
        """Rotations [deg] at every probe scenario, rest and 10 N*m flexion internal loads, compression share."""
        m = self.fsu.model
        rows = self.rot_rows
        phi = so3.log(R[rows, 0] @ R[0, 0].T)                       # one batch: every moment scenario
        deg = np.degrees(phi[np.arange(len(rows)), self.rot_axis] * self.rot_sign)
        rot = {self.scen[i][1:]: float(v) for i, v in zip(rows, deg)}
        sel = self.sel
        gf = m.group_forces(x[sel], R[sel], self.fm[sel])
        cf = m.contact_forces(x[sel], R[sel], self.cm[sel])
        kinds = self.kinds
        # ligament moments about the disc centre at 10 N*m flexion, straight from the fibre forces
        i = sel[1]
        _, _, T, _, d, dn, pa, _ = m.fibre_state(x[[i]], R[[i]], self.fm[[i]])
        f = -T[..., None] * d / dn[..., None]                     # force on the upper vertebra at pa
        st = self.st
        centre = x[i, st.upper] + R[i, st.upper] @ (st.centre - m.c[st.upper])
        mom = np.cross(pa[0] - centre, f[0])[:, 1]                # flexion component (world y)
        flex_moment = {k: float(-mom[mask].sum()) for k, mask in self.group_masks.items()}
        # facets' share of the follower load: their contact forces along the disc normal (masked residuals)
        j = [sel[2]]
        base, _ = m.evaluate(x[j], R[j], None, self.fm[j] * 0, self.cm[j] * 0, jacobian=False)
        onlyf, _ = m.evaluate(x[j], R[j], None, self.fm[j] * 0, self.cm[j], jacobian=False)
        up = float((onlyf - base)[0, st.upper, :3] @ m.discs[st.disc].frame[2])
        dl = m.disc_loads(x, R)                                    # every scenario in one batch
        disc_up = float(dl["force"][j[0], st.disc, 2])
        disc_r = dl["r"][:, st.disc, 2]                            # axial displacement [m], < 0 = compression
        moment_rows = [i for i, sc in enumerate(self.scen) if sc[0] != "compression"]
        return {"rot": rot, "min_disc_compression_mm": float(-disc_r[moment_rows].max() * 1e3),
                "rest_tension": {k: float(gf[0, g].sum()) for k, g in kinds.items()},
                "rest_facet": cf[0].copy(),
                "flex_tension": {k: float(gf[1, g].sum()) for k, g in kinds.items()},
                "flex_moment": flex_moment, "remus": self._remus_pairs(x, R),
                "compression_facet_share": max(up, 0.0) / max(max(up, 0.0) + max(disc_up, 0.0), 1e-9)}


@dataclass
class AdmissibleFit(RealFit):
    """:class:`RealFit` of :func:`fit_admissible` plus its last probe (metrics at the fitted set) and penalties."""

    probe: dict = field(default_factory=dict)
    penalties: pd.DataFrame | None = None
    prior: object = None
    posterior: Posterior | None = None
    objective: object = None


def _set_with(charset, names, q):
    """The characteristic set at fit vector ``q`` (log10 force scales, pre-elongation changes [mm], log10 facet
    stiffness, log10 disc shear stiffness)."""
    ligs = dict(charset.ligaments)
    facet, disc = charset.facet, charset.disc
    for name, v in zip(names, q):
        kind, what = name.split(":") if ":" in name else (name, "")
        if what == "scale":
            law = ligs[kind]
            ligs[kind] = dataclasses.replace(law, a=law.a * 10.0 ** v, c=law.c * 10.0 ** v)
        elif what == "pre_elongation":
            law = ligs[kind]
            ligs[kind] = dataclasses.replace(law, prestrain_pct=law.prestrain_pct + 100.0 * v * 1e-3 / law.law_length_m)
        elif name == "facet_stiffness":
            facet = dataclasses.replace(facet, stiffness=10.0 ** v)
        elif name == "disc_shear":
            disc = dataclasses.replace(disc, k_shear=10.0 ** v)
        elif kind == "disc_torque":
            p1, p2, p3 = disc.torque[what]
            disc = dataclasses.replace(disc, torque={**disc.torque, what: (p1 * 10.0 ** v, p2, p3 * 10.0 ** v)})
    return dataclasses.replace(charset, ligaments=ligs, facet=facet, disc=disc)


def shift_parameter(charset, name: str, delta: float):
    """``charset`` with the admissible fit's parameter ``name`` moved by ``delta`` in fit units (a force or torque
    scale by 10**delta, a pre-elongation by delta mm, the facet or disc shear stiffness by 10**delta): the
    perturbation of a prediction's finite-difference gradient for the posterior bands
    (:func:`lumbar.experiments.posterior.linearised_band`)."""
    if name == "facet_stiffness":
        return _set_with(charset, [name], [math.log10(charset.facet.stiffness) + delta])
    if name == "disc_shear":
        return _set_with(charset, [name], [math.log10(charset.disc.k_shear) + delta])
    return _set_with(charset, [name], [delta])


def _fit_penalties(mt, limit, nz):
    """(name, value) of every one-sided penalty term of :func:`fit_admissible` (0 inside its margin)."""
    p = []
    for side, f in zip(("left", "right"), mt["rest_facet"]):
        p.append((f"unloaded facet {side}", max(0.0, f - FIT_MARGIN["rest_facet_n"]) / 5.0))
    for k, lim in limit.items():
        v = mt["rest_tension"].get(k, 0.0)
        p.append((f"unloaded {k} tension", max(0.0, v - FIT_MARGIN["pretension_fraction"] * lim -
                                               0.5 * ADM.REST_TENSION_TOL_N) / max(0.25, 0.2 * lim)))
    for plane, (dp, dn) in ADM.NZ_PLANES.items():
        if plane in nz:
            ref = nz[plane][0]
            v = mt["rot"][(dp, 1.0)] + mt["rot"][(dn, 1.0)]
            p.append((f"neutral zone {plane}", max(0.0, FIT_MARGIN["nz_fraction"] * ref - v) / (0.25 * ref)))
    for k in ADM.FUNCTIONAL_KINDS:
        if k in mt["flex_tension"]:
            p.append((f"{k} in tension in flexion", max(0.0, FIT_MARGIN["functional_n"] - mt["flex_tension"][k])))
    fm_ = mt["flex_moment"]
    share = (fm_.get("ISL", 0.0) + fm_.get("SSL", 0.0)) / PROBE_MOMENTS[-1]
    p.append(("ISL+SSL share", max(0.0, FIT_MARGIN["isl_ssl_share"] - share) / 0.02))
    if "ISL" in mt["flex_tension"] and "SSL" in mt["flex_tension"]:
        p.append(("ISL above SSL", max(0.0, mt["flex_tension"]["SSL"] - 0.9 * mt["flex_tension"]["ISL"]) / 5.0))
    if "CL" in fm_ and "FL" in fm_:
        p.append(("CL above FL", max(0.0, fm_["FL"] - 0.9 * fm_["CL"]) / 0.2))
    Ms = (0.0,) + PROBE_MOMENTS
    for d in PROBE_DIRECTIONS:
        th = [0.0] + [mt["rot"][(d, M)] for M in PROBE_MOMENTS]
        p.append((f"first step {d}", max(0.0, th[1] - FIT_MARGIN["first_step_deg"]) / 0.05))
        c = [(th[i + 1] - th[i]) / (Ms[i + 1] - Ms[i]) for i in range(len(th) - 1)]
        i0 = Ms.index(COMPLIANCE_REFERENCE_WINDOW[0])
        ref = max(c[i0], 1e-6)
        p.append((f"compliance {d}", max(0.0, max(c[i0 + 1:]) / ref - 1.0 - FIT_MARGIN["compliance_rise"]) / 0.05))
    p.append(("compression facet share", max(0.0, mt["compression_facet_share"] - FIT_MARGIN["compression_share"]) / 0.05))
    # the paper's disc transmits no traction: where a pure moment lifts the upper vertebra off it, the unit's stiffness
    # drops (a compliance rise; measured in extension, where the facets' contact pushes the vertebra up): keep the
    # disc compressed by the ligaments' pre-tension at every probe moment
    p.append(("disc stays compressed", max(0.0, FIT_MARGIN["disc_compression_mm"] - mt["min_disc_compression_mm"]) /
              FIT_MARGIN["disc_compression_mm"]))
    return p


def _scale_penalties(names, q, mt):
    """(name, value) of the force-scale criterion inside :func:`fit_admissible`: a ligament's force scale outside
    [``ADM.SCALE_MIN``, ``ADM.SCALE_MAX``] x its source law must keep its tension within ``ADM.REMUS_FACTOR`` (less a
    margin) of the Remus et al. (2021) law of the same fibres where that law loads it most (metrics ``remus``), when
    it carries more than 1 N there (the criterion's own exception); elsewhere the scale itself is pulled back inside. Zero
    inside the range narrowed by ``FIT_MARGIN["scale_factor"]`` (a fit that trades the pull against the data ends
    inside the criterion's limit, not on it); continuous in the fit vector (the pull fades in over 0.05 decade)."""
    p = []
    remus = mt.get("remus") or {}
    margin = math.log10(FIT_MARGIN["scale_factor"])
    lo, hi = math.log10(ADM.SCALE_MIN) + margin, math.log10(ADM.SCALE_MAX) - margin
    allowed = math.log(ADM.REMUS_FACTOR / FIT_MARGIN["remus_factor"])
    for j, n in enumerate(names):
        if not n.endswith(":scale"):
            continue
        k = n.split(":")[0]
        out = max(0.0, lo - q[j]) + max(0.0, q[j] - hi)
        if out == 0.0:
            p.append((f"force scale {k}", 0.0))
            continue
        t_model, t_remus = remus.get(k, (0.0, 0.0))
        if t_remus > 1.0:
            log_ratio = math.log(max(t_model, 1e-9) / t_remus)
            miss = max(0.0, -allowed - log_ratio) if q[j] < lo else max(0.0, log_ratio - allowed)
            p.append((f"force scale {k}", min(1.0, out / 0.05) * miss / 0.1))
        else:
            p.append((f"force scale {k}", out / 0.05))
    return p


def _rom_of(mt, directions):
    out = []
    for d in directions:
        if d in ("lateral_bending", "axial_rotation"):
            sides = ("right", "left")
            out.append(0.5 * (mt["rot"][(f"{d}_{sides[0]}", 10.0)] + mt["rot"][(f"{d}_{sides[1]}", 10.0)]))
        else:
            out.append(mt["rot"][(d, 10.0)])
    return np.array(out)


#: columns of the table of the rows the final, admissibility-constrained fit is pinned to
TARGET_COLUMNS = ("stage", "direction", "moment_nm", "rom_mean_deg", "rom_min_deg", "rom_max_deg", "n_specimens", "kind",
                  "source")


def admissible_fit_targets(reference: pd.DataFrame, real_targets: pd.DataFrame | None = None,
                           moment_nm: float = 10.0) -> tuple[pd.DataFrame | None, str]:
    """The intact-unit ROM rows at ``moment_nm`` that the final fit (real rows plus the admissibility criteria,
    :func:`fit_admissible`) is pinned to, and where they come from.

    A measured reference table (no ``surrogate`` row) that has intact rows at ``moment_nm``: those rows, the same
    specimens as every other stage of the table (``real_targets``, e.g. Yamamoto et al. 1989, then stay an
    independent check). Otherwise ``real_targets``: a surrogate is made by this model and carries no information
    about real specimens. None when neither has such rows (the calibration then ends at the stepwise fits, without
    the admissibility constraints; the caller says so)."""
    def intact(t):
        if t is None or not len(t):
            return None
        sel = t[(t["stage"] == "intact") & np.isclose(t["moment_nm"].astype(float), moment_nm)]
        return sel.reset_index(drop=True) if len(sel) else None

    measured = "kind" in reference.columns and not (reference["kind"] == "surrogate").any()
    own = intact(reference) if measured else None
    if own is not None:
        return own, f"the measured table's intact rows at {moment_nm:g} N*m"
    real = intact(real_targets)
    if real is not None:
        return real, f"the real intact rows at {moment_nm:g} N*m of stepwise_reduction.real_targets"
    return None, "none"


def fit_admissible(geometry, charset, targets: pd.DataFrame, level="L4-L5", published=None, geometry_path=None,
                   k_shear=None, max_iter=50, tol=1e-8, max_nfev=100,
                   nz_reference=None, start: dict | None = None, prior_spread: dict | None = None,
                   data_sd_rel: float = DATA_SD_REL, fit_disc_torque: bool = True,
                   disc_rows: pd.DataFrame | None = None) -> AdmissibleFit:
    """Fit a characteristic set to real ROM rows AND the admissibility criteria (constrained least squares).

    Parameters (bounded; ``least_squares(method="trf")``): per ligament on elongation, log10 of its force scale in
    FIT_SCALE_BOUNDS (a and c scaled; a scale outside the admissible 0.1-10 x of
    :mod:`lumbar.experiments.admissibility` must be explained by the Remus et al. model of these fibres) and a change of its pre-elongation (slack by up to
    PRE_ELONGATION_SLACK_MM, prestrain at most MAX_PRESTRAIN_PCT of the law length; never
    leaving a slack length below ``fsu.MIN_SLACK_FRACTION`` of a fibre); log10 facet contact stiffness in
    FACET_STIFFNESS_RANGE; log10 disc shear stiffness in its sourced range.
    Residuals: (sim - measured) / (25 % of measured) per target row (the acceptance band of the validation) plus a
    steep one-sided term beyond FIT_MARGIN["rom_rel"]; the admissibility criteria as one-sided penalties (weight
    PENALTY_WEIGHT, active only beyond FIT_MARGIN, inside the criteria's limits): unloaded facet contact and ligament
    tensions (:func:`admissibility.pretension_limits`), the neutral-zone proxy, the rotation of the first 0.25 N*m step,
    ISL/SSL/FL/CL in tension and the ISL+SSL share at 10 N*m flexion, the ordering ISL > SSL and CL > FL moment, the
    compliance not rising from 2.5 to 10 N*m, the facets' share of a 1000 N follower load; and the prior: (parameter
    - prior centre) / prior spread for every parameter (``prior_spread``: {name: spread in fit units}, default
    :func:`lumbar.experiments.priors.default_spreads`; the centre is ``charset``'s own value, i.e. force scale 1 and
    no pre-elongation change for the ligaments). The data rows enter as (sim - measured) / (``data_sd_rel`` x
    measured). The minimum is a MAP estimate (penalties = soft constraints); its Laplace posterior (the Gauss-Newton
    Hessian of the same stacked residuals at the optimum) is :attr:`AdmissibleFit.posterior`. The Jacobian is finite
    differences of the linearised equilibria (one Newton step per parameter, :class:`_Probe`). ``start``: {parameter
    name: value in fit units} to start from (e.g. a previous fit). The admissibility of the result is checked
    afterwards on 0.25 N*m curves (:func:`admissibility.evaluate`).
    """
    t = targets.reset_index(drop=True)
    if t.empty:
        raise ValueError("fit_admissible: no target rows")
    if not set(t["stage"]) <= {"intact"} or not np.allclose(t["moment_nm"], 10.0):
        raise ValueError("fit_admissible: the targets must be intact-unit ROM rows at 10 N*m (e.g. Yamamoto et al. "
                         "1989)")
    measured = t["rom_mean_deg"].to_numpy(float)
    published = published if published is not None else load_characteristic_set("calibrated")
    limits = ADM.pretension_limits(published, charset, geometry, level, geometry_path)
    limit = dict(zip(limits["ligament"], limits["limit_n"]))
    nz = nz_reference if nz_reference is not None else ADM.neutral_zones(level)
    ks0 = float(k_shear if k_shear is not None else charset.disc.k_shear)
    names, lo, hi, x0 = [], [], [], []
    lev = geometry.levels[level]
    for kind, law in charset.ligaments.items():
        if not hasattr(law, "a"):
            continue
        names.append(f"{kind}:scale")
        lo.append(math.log10(FIT_SCALE_BOUNDS[0]))
        hi.append(math.log10(FIT_SCALE_BOUNDS[1]))
        x0.append(0.0)
        if law.law_length_m is not None:
            lens = [np.linalg.norm(np.asarray(g.upper) - np.asarray(g.lower), axis=1) + np.asarray(g.extra_length)
                    for g in lev.ligaments if g.kind == kind]
            shortest = min(float(v.min()) for v in lens) if lens else 1.0
            # at most MAX_PRESTRAIN_PCT of the law length, and a margin to the hard slack-length limit of this level
            e_max = min(MAX_PRESTRAIN_PCT / 100.0 * law.law_length_m,
                        (1.0 - 1.25 * MIN_SLACK_FRACTION) * shortest) - law.pre_elongation_m
            names.append(f"{kind}:pre_elongation")
            # down to slack by at least PRE_ELONGATION_SLACK_MM at rest, whatever the prior's pre-elongation
            lo.append(-max(law.pre_elongation_m * 1e3, 0.0) - PRE_ELONGATION_SLACK_MM)
            hi.append(float(e_max * 1e3))
            x0.append(0.0)
    names.append("facet_stiffness")
    lo.append(math.log10(FACET_STIFFNESS_RANGE[0]))
    hi.append(math.log10(FACET_STIFFNESS_RANGE[1]))
    x0.append(float(np.clip(math.log10(charset.facet.stiffness), lo[-1], hi[-1])))
    if charset.disc.k_shear_range is not None:
        names.append("disc_shear")
        lo.append(math.log10(charset.disc.k_shear_range[0]))
        hi.append(math.log10(charset.disc.k_shear_range[1]))
        x0.append(float(np.clip(math.log10(ks0), lo[-1], hi[-1])))
    if fit_disc_torque:
        for d in charset.disc.torque:
            names.append(f"disc_torque:{d}")
            lo.append(math.log10(DISC_TORQUE_SCALE_BOUNDS[0]))
            hi.append(math.log10(DISC_TORQUE_SCALE_BOUNDS[1]))
            x0.append(0.0)
    lo, hi, prior_q = np.array(lo), np.array(hi), np.array(x0)
    q_start = prior_q.copy()
    for j, n in enumerate(names):
        if start and n in start:
            q_start[j] = float(np.clip(start[n], lo[j], hi[j]))
    base = charset if k_shear is None else dataclasses.replace(
        charset, disc=dataclasses.replace(charset.disc, k_shear=ks0))
    fsu = build_fsu(geometry, base, level, follower=True)
    m = fsu.model
    groups = {k: [g for g, (_, kk, _lv) in enumerate(m.fibre_groups) if kk == k] for k in charset.ligaments}
    k0 = m.k_stiff.copy()
    probe = _Probe(fsu, max_iter=max_iter, tol=tol)
    if geometry_path is not None:
        from ..geometry.visible_human import read_uw_materials  # noqa: PLC0415
        probe.set_remus(read_uw_materials(geometry_path, level))
    n_eval = [0, 0]
    n_res = [None]              # length of a residual vector (a failed probe returns one of the same length)

    def apply(q):
        cs = _set_with(base, names, q)
        for kind, law in cs.ligaments.items():
            if hasattr(law, "a") and groups.get(kind):
                set_ligament_law(m, groups[kind], law)
        m.k_stiff[:] = k0 * (cs.facet.stiffness / base.facet.stiffness)
        for d in m.discs:
            d.k_shear = cs.disc.k_shear
            d.torque = dict(cs.disc.torque)
        return cs

    directions = list(t["direction"])
    last = {}

    prior_sd = np.array([(prior_spread or {}).get(n, d) for n, d in zip(names, default_spreads(names, lo, hi))], float)
    if np.any(~np.isfinite(prior_sd)) or np.any(prior_sd <= 0):
        raise ValueError(f"fit_admissible: every prior spread must be finite and > 0, got {dict(zip(names, prior_sd))}")

    # the disc-only rows (the stage the disc law was fitted on) as data too, in torque space at the measured angle
    # (Eq. 3 as step 1 fits it): the disc torque scales are then informed by their own data, not only by a prior
    dr = [] if disc_rows is None or not fit_disc_torque else \
        [(str(r.direction), float(r.moment_nm), math.radians(float(r.rom_mean_deg)))
         for r in disc_rows.itertuples(index=False) if str(r.direction) in charset.disc.torque]
    torque_idx = {n.split(":")[1]: j for j, n in enumerate(names) if n.startswith("disc_torque:")}

    def disc_residuals(q):
        out = []
        for d, M, phi in dr:
            p1, p2, p3 = charset.disc.torque[d]
            sc = 10.0 ** q[torque_idx[d]] if d in torque_idx else 1.0
            out.append((float(eq3(phi, (p1 * sc, p2, p3 * sc))) - M) / (data_sd_rel * M))
        return np.array(out)

    def from_metrics(q, mt):
        pen = _fit_penalties(mt, limit, nz) + _scale_penalties(names, q, mt)
        rel = (_rom_of(mt, directions) - measured) / measured
        edge = np.maximum(0.0, np.abs(rel) - FIT_MARGIN["rom_rel"]) / 0.05
        return np.concatenate([rel / data_sd_rel, disc_residuals(q), PENALTY_WEIGHT * edge,
                               PENALTY_WEIGHT * np.array([v for _, v in pen]), (q - prior_q) / prior_sd]), pen

    def residual_names(pen):
        return [f"ROM {d} (data)" for d in directions] + \
            [f"disc-only {d} {M:g} N*m (data)" for d, M, _ in dr] + \
            [f"ROM {d} (25 % band constraint)" for d in directions] + [n for n, _ in pen] + [f"prior {n}" for n in names]

    def residual(q):
        apply(q)
        n_eval[0] += 1
        x, R, ok = probe.run()
        if not ok:
            last.clear()
            return np.full(n_res[0] or 2 * len(measured) + len(dr) + 40 + len(q), PENALTY)
        mt = probe.metrics(x, R)
        r, pen = from_metrics(q, mt)
        n_res[0] = len(r)
        last.update(q=np.array(q), mt=mt, pen=pen, r=r)
        return r

    def jacobian(q):
        if last.get("q") is None or not np.array_equal(last["q"], q) or probe.state is None:
            residual(q)
        if probe.state is None:
            return np.zeros((len(last.get("r", np.zeros(1))), len(q)))
        r0 = last["r"]
        Jm = np.empty((len(r0), len(q)))
        for j in range(len(q)):
            h = 1e-4 * max(1.0, abs(q[j]))
            h = -h if q[j] + h > hi[j] else h
            qj = np.array(q, float)
            qj[j] += h
            apply(qj)
            n_eval[1] += 1
            x, R = probe.linearised()
            Jm[:, j] = (from_metrics(qj, probe.metrics(x, R))[0] - r0) / h
        apply(q)
        return Jm

    if not start:
        # no start given: the best of a one-dimensional scan of one common force scale of every ligament (the prior
        # laws are an order of magnitude too stiff or too soft on a geometry they were not calibrated on)
        best = None
        for s_ in START_SCALES:
            q_try = prior_q.copy()
            q_try[[j for j, n in enumerate(names) if n.endswith(":scale")]] = math.log10(s_)
            q_try = np.clip(q_try, lo, hi)
            probe.warm = None
            r_try = residual(q_try)
            cost_try = float(r_try @ r_try)
            if best is None or cost_try < best[0]:
                best = (cost_try, q_try)
        q_start = best[1]
        probe.warm = None
    r_start = residual(q_start)
    sol = least_squares(residual, q_start, jac=jacobian, method="trf", bounds=(lo, hi), x_scale=0.3, xtol=1e-6,
                        ftol=1e-6, gtol=1e-6, max_nfev=max_nfev)
    q = sol.x
    residual(q)
    if not last:
        raise RuntimeError("fit_admissible: the fitted set has no equilibrium in every probe scenario")
    J_map = jacobian(q)
    residual(q)
    post = laplace_posterior(names, q, prior_q, prior_sd, lo, hi, J_map, last["r"], residual_names(last["pen"]),
                             n_data=len(measured) + len(dr))
    cs = _set_with(base, names, q)
    cs = dataclasses.replace(cs, ligaments={k: dataclasses.replace(v, source="calibrated on elongation (fit_admissible)")
                                            for k, v in cs.ligaments.items()})
    mt = last["mt"]
    rom = _rom_of(mt, directions)
    width = hi - lo
    at_bound = (q - lo <= AT_BOUND_FRACTION * width) | (hi - q <= AT_BOUND_FRACTION * width)
    rows = []
    for j, n in enumerate(names):
        if n.endswith(":scale") or n.startswith("disc_torque:"):
            value, unit, start_v, lower, upper, bu = 10.0 ** q[j], "force scale (-)", 1.0, 10.0 ** lo[j], \
                10.0 ** hi[j], "force scale (-)"
        elif n.endswith(":pre_elongation"):
            value, unit, start_v, lower, upper, bu = q[j], "mm (change)", 0.0, lo[j], hi[j], "mm"
        else:
            value, unit, start_v, lower, upper, bu = 10.0 ** q[j], "N/m", 10.0 ** prior_q[j], 10.0 ** lo[j], \
                10.0 ** hi[j], "N/m"
        rows.append({"parameter": n, "start": start_v, "value": value, "unit": unit, "fit_value": float(q[j]),
                     "lower": lower, "upper": upper, "bound_unit": bu, "identifiable": True,
                     "at_bound": bool(at_bound[j]), "bound_reason": BOUND_REASONS.get(n, "") if at_bound[j] else ""})
    tt = t[["stage", "direction", "moment_nm", "rom_mean_deg"]].copy()
    tt["rom_sim_deg"] = rom
    tt["rel_error"] = (rom - measured) / measured
    tt["converged"] = True
    pen = pd.DataFrame([{"penalty": n, "value": v} for n, v in last["pen"]])
    log.info("admissible fit: %d residual and %d linearised evaluations, cost %.4g -> %.4g; ROM %s deg; active "
             "penalties: %s", n_eval[0], n_eval[1], 0.5 * float(r_start @ r_start), float(sol.cost),
             np.round(rom, 2).tolist(), ", ".join(f"{n} {v:.2g}" for n, v in last["pen"] if v > 0) or "none")
    fit = AdmissibleFit(cs, pd.DataFrame(rows), tt, float(sol.cost), n_eval[0], probe=mt, penalties=pen,
                        prior=charset, posterior=post)
    fit.objective = residual          # q (fit units) -> the stacked residuals: for a sampling check of the posterior
    return fit


POSTERIOR_COLUMNS = ("parameter", "unit", "fit_unit", "prior_centre", "prior_90_low", "prior_90_high",
                     "prior_centre_fit", "prior_spread_fit", "map", "posterior_90_low", "posterior_90_high", "map_fit",
                     "posterior_spread_fit", "spread_ratio", "shift_prior_sd", "moved_by", "data_moved_it", "at_bound",
                     "bound_reason", "prior_source", "prior", "data_spread")


def posterior_tables(fit: AdmissibleFit | None, prior_name: str = "") -> tuple[pd.DataFrame, pd.DataFrame]:
    """(results/calibration/posterior.csv, posterior_covariance.csv) of the final admissible fit: per parameter the
    prior (centre, spread, source), the MAP, the Laplace 90 % interval, posterior/prior spread, which rows moved it
    and the at-bound flag with its reason (:func:`lumbar.experiments.posterior.posterior_table`); empty tables with
    the columns when there was no admissible fit (a strain-transfer calibration)."""
    from .posterior import covariance_table, posterior_table  # noqa: PLC0415 - only the calibration writes them
    from .priors import prior_sources  # noqa: PLC0415

    if fit is None or fit.posterior is None:
        return pd.DataFrame(columns=list(POSTERIOR_COLUMNS)), \
            pd.DataFrame(columns=["parameter_i", "parameter_j", "covariance"])
    post = fit.posterior
    src = prior_sources(post.names, prior_name or "table3")
    for n in post.names:
        if n.startswith("disc_torque:"):
            src[n] = ("centre: the disc-only fit (step 1, Eq. 3 on the disc-only rows); spread: that of a measured "
                      f"row, {DATA_SD_REL:.0%} (assumed: no specimen spread published)")
    tab = posterior_table(post, src, BOUND_REASONS).assign(
        prior=prior_name, data_spread=f"{DATA_SD_REL:.0%} of each measured ROM row (assumed; none published)")
    return tab[list(POSTERIOR_COLUMNS)], covariance_table(post)


def read_fit_start(path) -> dict | None:
    """{parameter: fit value} of a :func:`fit_admissible` parameter table (e.g. the surrogate generator's anchoring,
    results/experiments/stepwise_reduction_generator_fit.csv), to start another fit from; None when the file is
    missing, empty or from another fit (no ``fit_value`` column)."""
    if not path or not Path(path).is_file():
        return None
    df = pd.read_csv(path)
    if df.empty or "fit_value" not in df.columns or "parameter" not in df.columns:
        return None
    return {str(p): float(v) for p, v in zip(df["parameter"], df["fit_value"]) if np.isfinite(v)}


#: documented reasons for fitted parameters that end at a bound (docs/validity.md, "Calibration findings"); a bound
#: without a reason here fails the admissibility criterion "fitted parameters at a bound without a documented reason"
BOUND_REASONS = {
    "ISL:scale": "the paper's Table 3 ISL on elongation is a stiff linear spring (18.7 N per % of its 29.9 mm fibre "
                 "beyond a 1 mm toe); the ISL of this unit stretches by several mm in flexion, so at the prior's "
                 "force it alone would exceed the 134 N Hindle et al. (1990) measured for ISL+SSL near the end of "
                 "flexion and hold the flexion ROM far below Yamamoto's: the lower end of the admissible range is the "
                 "measured upper limit of its force (docs/validity.md)",
    "FL:scale": "the FL prior (the Rupp et al. 2015 flavum of the paper's Appendix 1, about 110 N/mm) would carry more "
                "of the flexion moment than the capsules, against the ordering of Adams, Hutton & Stott (1980; CL 39 % "
                "vs FL 13 % at full flexion) and the flexion ROM (docs/validity.md)",
    "PLL:scale": "the PLL lies close to the disc centre (flexion lever about 15 mm per rad) and changes no ROM target "
                 "by more than a few hundredths of a degree; its scale is held down by its small sourced pre-tension "
                 "(2.3 N, the paper's law at its 10 % prestrain)",
    "disc_shear": "upper end of the sourced motion-segment range (53-140 N/mm): axial rotation turns about the "
                  "contacting facet, so the disc's shear stiffness (not its torsion law) resists it; the measured "
                  "axial rotation needs at least this stiffness (docs/validity.md)",
    "facet_stiffness": "the facet contact acts as a stiff pivot (cartilage contact); the ROM does not change between "
                       "1e6 and 1e7 N/m (docs/validity.md)",
}
