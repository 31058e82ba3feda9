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

Disc (step 1): :mod:`lumbar.experiments.calibration.disc`.

Ligaments (steps 2-8): Eq. 7 has four parameters, but (a, b, c, d) are not identifiable from ROM
(a shift of c trades against a and b). Project parametrisation: ``c = -a*ln(1 + exp(b/d))`` so that the
law is zero at 0 % strain (F(0) = 0, tension-only rule of ``lumbar.mechanics.elements.ligament`` unchanged), and
(a, b, d) are fitted with bounds a in [0.01, 5000] N, b in [-60, 40] %, d in [0.05, 50] % (d > 0:
monotone laws; the paper's concave FL, d < 0, is outside this family by design). The prestrains stay the
paper's (Sect. 2.2.4). Each fit is a ``least_squares(method="trf")`` with finite differences over that
stage's 20 scenarios (5 moments x 4 directions); each evaluation solves the stage's FSU batch (warm
started). Residual = (ROM_sim - ROM_mean) / width with width = max - min where the row has a range,
else 2 x ``tolerance_deg``; a scenario without equilibrium contributes a fixed penalty of 10.

The facet stiffness (step 4) is one parameter (log-scaled, bounds ``K_FACET_BOUNDS``: 100 N/m - 1e7 N/m).
This module never imports snakemake.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ...inputs.characteristics import SoftplusLaw, load_characteristic_set
from ..fsu import build_fsu, facet_surfaces, set_ligament_law
from ..stepwise_reduction import MAIN_DIRECTIONS, StageSolver
from . import influence
from .admissible import fit_admissible
from .common import AT_BOUND_FRACTION, IDENTIFIABLE_MIN_DEG, PENALTY, kind_groups, replace_fields, rom_widths, stage_rows
from .disc import DISC_STAGE, P1_MAX_NM, P1_MIN_NM, c_zero, eq3, fit_disc_direction
from .prior import calibration_prior
from .real_targets import fit_real_targets

log = logging.getLogger(__name__)

FACET_STAGE = "wo_cl"
LIGAMENT_STAGE = {"ALL": "wo_pll", "PLL": "wo_va", "CL": "wo_fl", "FL": "wo_isl", "ISL": "wo_ssl", "SSL": "intact"}
ORDER = [("disc", DISC_STAGE), ("ALL", "wo_pll"), ("PLL", "wo_va"), ("facets", FACET_STAGE),
         ("CL", "wo_fl"), ("FL", "wo_isl"), ("ISL", "wo_ssl"), ("SSL", "intact")]
CALIBRATED_LIGAMENTS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL")
A_BOUNDS, B_BOUNDS, D_BOUNDS = (0.01, 5000.0), (-60.0, 40.0), (0.05, 50.0)
K_FACET_BOUNDS = (100.0, 1.0e7)
F0_BOUNDS = (0.0, 300.0)
CONCAVE_CANDIDATES = ("FL",)


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


def _set_law(model, kind, a, b, d, law_length_m=None, prestrain_pct=0.0):
    set_ligament_law(model, kind_groups(model, kind),
                     SoftplusLaw(a, b, c_zero(a, b, d), d, prestrain_pct, law_length_m=law_length_m))


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


def _disc_step(base, reference, steps):
    """Step 1: Eq. 3 per direction on the disc-only stage; (the disc with the fitted torque laws, Fig. 4 points).
    Appends one summary row per direction to ``steps``."""
    rows = stage_rows(reference, DISC_STAGE)
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
        p1_bound = p[0] <= P1_MIN_NM + 1e-9 or p[0] >= P1_MAX_NM - 1e-9
        if p1_bound and p[0] <= P1_MIN_NM + 1e-9:
            log.info("calibration step 1 (disc %s): p1 at its bound %g N*m: the rows show no stiffening, the law is "
                     "linear (p3 = %.4g N*m/rad)", d, P1_MIN_NM, p[2])
        elif p1_bound:
            log.info("calibration step 1 (disc %s): p1 at its upper bound %g N*m (the rows ask for a step-like law; "
                     "p2 = %.3g rad^3, p3 = %.4g N*m/rad)", d, P1_MAX_NM, p[1], p[2])
        steps.append({"step": 1, "structure": f"disc:{d}", "stage": DISC_STAGE, "n_scenarios": len(r),
                      "parameters": "p1,p2,p3", "rms_residual": float(np.sqrt(np.mean(resid**2))),
                      "residual_unit": "N*m", "n_not_converged": 0, "n_evaluations": 1,
                      "identifiable": True, "at_bound": bool(p1_bound), "at_bound_parameters": "p1" if p1_bound else ""})
    return replace_fields(base.disc, torque=torque), disc_pts


def _start_set(base, disc, family, start):
    """The model set of steps 2-8: ``base`` with the fitted ``disc`` and every calibrated ligament at its start law
    (unfitted ones are masked by the stages); (set, {kind: start law}, the other ligaments of ``base``)."""
    start = dict(start or {})
    ligs = {}
    if family not in ("monotone", "scaled_published"):
        raise ValueError(f"calibration family {family!r}; expected 'monotone' or 'scaled_published'")
    for kind in CALIBRATED_LIGAMENTS:
        pre = base.ligaments[kind].prestrain_pct if kind in base.ligaments else 0.0
        pub = base.ligaments.get(kind)
        if family == "scaled_published" and pub is not None and hasattr(pub, "a"):
            ligs[kind] = replace_fields(pub, source="calibration start (published law)")
            continue
        a, b, d = start.get(kind, (20.0, -pre, 2.0))
        ligs[kind] = SoftplusLaw(a, b, c_zero(a, b, d), d, pre, source="calibration start",
                                 law_length_m=getattr(pub, "law_length_m", None))
    extra = {k: v for k, v in base.ligaments.items() if k not in CALIBRATED_LIGAMENTS}   # e.g. the ITL on elongation
    cs = replace_fields(base, name="calibrated", disc=disc, ligaments={**ligs, **extra},
                        absent={} if "ITL" in extra else
                        {"ITL": "no Table 3 row; the stepwise-reduction experiment does not isolate the ITL"})
    return cs, ligs, extra


class _StepwiseFit:
    """Steps 2-8 of :func:`calibrate` on one model (the start set of :func:`_start_set`): each structure of ORDER
    fitted on its stage, every other structure of that stage already calibrated. :meth:`fit_structure` records the
    step's summary row, its ROM per scenario and (ligaments) the Fig. 5 points."""

    def __init__(self, fsu, base, ligs, family, concave, tolerance_deg, surrogate_weight, max_iter, tol, max_nfev):
        self.fsu, self.m = fsu, fsu.model
        self.base, self.ligs, self.family, self.concave = base, ligs, family, concave
        self.tolerance_deg, self.surrogate_weight = tolerance_deg, surrogate_weight
        self.max_iter, self.tol, self.max_nfev = max_iter, tol, max_nfev
        self.k_fac0 = float(base.facet.stiffness)
        self.k_fac = self.k_fac0
        self.fitted = {}                 # kind -> (a, b, c, d)
        self.rom_fit, self.lig_pts = [], []

    def candidates(self, what):
        """The parameterisations ``what`` is fitted in: (apply(q), x0, lower, upper, x_scale, q -> (a, b, c, d) or
        None). Facets: log10 c_stiff. A ligament: the monotone branch (d > 0, F(0) = 0) and, for the ``concave``
        kinds, the concave one (d < 0, F(0) = F0 >= 0); family scaled_published: only the force scale and knee shift
        of the start law."""
        m, family = self.m, self.family
        candidates = []
        if what == "facets":
            def apply_f(q):
                m.set_facet_stiffness(10.0 ** q[0])
            candidates.append((apply_f, [math.log10(self.k_fac)], [math.log10(K_FACET_BOUNDS[0])],
                               [math.log10(K_FACET_BOUNDS[1])], [0.3], None))
        else:
            kind = what
            law = self.ligs[kind]
            if family == "scaled_published":
                def apply_s(q, kind=kind, law=law):     # published shape: force scale and knee shift
                    sc = 10.0 ** q[0]
                    set_ligament_law(m, kind_groups(m, kind), replace_fields(law, a=law.a * sc, b=law.b + q[1],
                                                                             c=law.c * sc))
                candidates.append((apply_s, [0.0, 0.0], [-3.0, -20.0], [1.0, 20.0], [0.3, 2.0],
                                   lambda q, law=law: (law.a * 10.0 ** q[0], law.b + q[1], law.c * 10.0 ** q[0],
                                                       law.d)))

            def apply_m(q, kind=kind, law=law):  # monotone branch: d > 0, F(0) = 0
                _set_law(m, kind, 10.0 ** q[0], q[1], 10.0 ** q[2], law.law_length_m, law.prestrain_pct)
            if family == "scaled_published":
                law = replace_fields(law, a=20.0, b=-law.prestrain_pct, d=2.0)   # unused: only candidate 0 is fitted
            candidates.append((apply_m, [math.log10(law.a), law.b, math.log10(law.d)],
                               [math.log10(A_BOUNDS[0]), B_BOUNDS[0], math.log10(D_BOUNDS[0])],
                               [math.log10(A_BOUNDS[1]), B_BOUNDS[1], math.log10(D_BOUNDS[1])], [0.3, 2.0, 0.3],
                               lambda q: (10.0 ** q[0], q[1], c_zero(10.0 ** q[0], q[1], 10.0 ** q[2]), 10.0 ** q[2])))
            if kind in self.concave:
                def apply_c(q, kind=kind, law=law):  # concave branch: d < 0, F(0) = F0 >= 0 fitted
                    a, b, d, f0 = 10.0 ** q[0], q[1], -(10.0 ** q[2]), q[3]
                    set_ligament_law(m, kind_groups(m, kind), replace_fields(law, a=a, b=b, c=f0 + c_zero(a, b, d),
                                                                             d=d))
                candidates.append((apply_c, [1.5, 0.0, 1.0, 50.0],
                                   [math.log10(A_BOUNDS[0]), B_BOUNDS[0], math.log10(D_BOUNDS[0]), F0_BOUNDS[0]],
                                   [math.log10(A_BOUNDS[1]), B_BOUNDS[1], math.log10(D_BOUNDS[1]), F0_BOUNDS[1]],
                                   [0.3, 2.0, 0.3, 20.0],
                                   lambda q: (10.0 ** q[0], q[1],
                                              q[3] + c_zero(10.0 ** q[0], q[1], -(10.0 ** q[2])), -(10.0 ** q[2]))))
        if family == "scaled_published":
            candidates = candidates[:1]
        return candidates

    @staticmethod
    def identifiable(candidates, residual, w):
        """Does a step of any parameter (of the first candidate) change the stage's ROM by IDENTIFIABLE_MIN_DEG?"""
        apply0, x00, lb0, ub0, xs0 = candidates[0][:5]
        x00 = np.clip(x00, lb0, ub0)
        r_base = residual(x00, apply0) * w
        for j in range(len(x00)):
            dq = np.array(x00, float)
            dq[j] = dq[j] + (xs0[j] if dq[j] + xs0[j] <= ub0[j] else -xs0[j])
            if np.nanmax(np.abs(residual(dq, apply0) * w - r_base)) >= IDENTIFIABLE_MIN_DEG:
                return True
        return False

    def best_fit(self, candidates, residual):
        """The least-squares fit of every candidate, the best applied to the model: (solution, q -> law, indices of
        the parameters at a bound)."""
        from scipy.optimize import least_squares  # noqa: PLC0415 - scipy.optimize (about a second) only where a fit runs
        best = None
        for apply, x0, lb, ub, xs, to_law in candidates:
            x0 = np.clip(x0, lb, ub)
            sol = least_squares(lambda q: residual(q, apply), x0, method="trf", bounds=(lb, ub), x_scale=xs,
                                diff_step=1e-5, xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=self.max_nfev)
            if best is None or sol.cost < best[0].cost - 1e-12:
                best = (sol, apply, to_law, np.asarray(lb, float), np.asarray(ub, float))
        sol, apply, to_law, lb, ub = best
        apply(sol.x)
        span = ub - lb
        at_bound = [j for j in range(len(sol.x))
                    if sol.x[j] - lb[j] <= AT_BOUND_FRACTION * span[j] or ub[j] - sol.x[j] <= AT_BOUND_FRACTION * span[j]]
        xs = next(c[4] for c in candidates if c[0] is apply)
        return sol, to_law, at_bound, (apply, sol.x, lb, ub, xs, to_law)

    def keep_start(self, what):
        """A structure that is not identifiable keeps the start set's value (a ligament: the start set's law)."""
        m = self.m
        if what == "facets":
            m.set_facet_stiffness(self.k_fac0)
        else:
            pub = self.base.ligaments.get(what)
            if pub is not None and hasattr(pub, "a"):
                set_ligament_law(m, kind_groups(m, what), pub)

    def fit_structure(self, step, what, stage, reference):
        """Fit ``what`` on ``stage`` of ``reference``; returns the step's calibration_summary row."""
        m = self.m
        rows = stage_rows(reference, stage)
        w = rom_widths(rows, self.tolerance_deg)
        if "kind" in rows.columns:
            w = w / np.where(rows["kind"].to_numpy() == "surrogate", float(self.surrogate_weight), 1.0)
        target = rows["rom_mean_deg"].to_numpy(float)
        ss = StageSolver(self.fsu, rows[["stage", "direction", "moment_nm"]], max_iter=self.max_iter, tol=self.tol)
        n_eval = [0]

        def residual(q, apply):
            apply(q)
            n_eval[0] += 1
            rom, conv, _ = ss.run()
            return np.where(conv, (rom - target) / w, PENALTY)

        candidates = self.candidates(what)
        identifiable = self.identifiable(candidates, residual, w)
        at_bound, sol, not_fixed = [], None, ""
        if not identifiable:
            self.keep_start(what)
            log.info("calibration step %d (%s on %s): not identifiable (no ROM of the stage changes by %.2g "
                     "deg when its parameters change): kept at the start set's value", step, what, stage,
                     IDENTIFIABLE_MIN_DEG)
        else:
            sol, to_law, at_bound, found = self.best_fit(candidates, residual)
            # identifiable where the fit started need not mean identifiable where it ended: a law moved to where it
            # carries (almost) nothing over the stage changes no ROM any more, so the data do not fix it there
            # (a structure slack in the experiment). Flagged, the fitted value kept.
            if not self.identifiable([found], residual, w):
                identifiable = False
                not_fixed = (" (not identifiable at the fit: no ROM of the stage changes by "
                             f"{IDENTIFIABLE_MIN_DEG:.2g} deg when its parameters change there)")
                log.info("calibration step %d (%s on %s): the fit ends where no ROM of the stage responds to it: "
                         "flagged not identifiable", step, what, stage)
            found[0](sol.x)
        rom, conv, res = ss.run()
        fitted = self.fitted
        if not identifiable and sol is None:
            if what == "facets":
                params = f"c_stiff={self.k_fac:.6g} N/m (not identifiable: start value)"
            else:
                pub = self.base.ligaments.get(what)
                ligs = self.ligs
                fitted[what] = (pub.a, pub.b, pub.c, pub.d) if pub is not None and hasattr(pub, "a") else \
                    tuple(float(v) for v in (ligs[what].a, ligs[what].b, ligs[what].c, ligs[what].d))
                params = "a={:.5g} N, b={:.5g} %, c={:.5g} N, d={:.5g} % (not identifiable: start set)".format(
                    *fitted[what])
        elif what == "facets":
            self.k_fac = 10.0 ** sol.x[0]
            params = f"c_stiff={self.k_fac:.6g} N/m" + not_fixed
        else:
            fitted[what] = tuple(float(v) for v in to_law(sol.x))
            params = "a={:.5g} N, b={:.5g} %, c={:.5g} N, d={:.5g} %".format(*fitted[what]) + not_fixed
            # Fig. 5 data: group strain and force at the stage's solutions (and its 0 N*m state)
            _, strain, *_ = m.fibre_state(res.x, res.R)
            gf = m.group_forces(res.x, res.R)
            for g in kind_groups(m, what):
                sel = m.f_group == g
                for i in range(len(rows)):
                    if conv[i]:
                        self.lig_pts.append({"ligament": what, "group": m.fibre_groups[g][0], "stage": stage,
                                             "direction": rows["direction"][i], "moment_nm": rows["moment_nm"][i],
                                             "strain_pct": float(strain[i, sel].mean()), "force_n": float(gf[i, g])})
        err = rom - target
        names = ["log10 c_stiff"] if what == "facets" else (
            ["log10 force scale", "knee shift db"] if self.family == "scaled_published" else
            ["log10 a", "b", "log10 |d|", "F0"])
        summary = {"step": step, "structure": what, "stage": stage, "n_scenarios": len(rows),
                   "parameters": params, "rms_residual": float(np.sqrt(np.nanmean(err**2))),
                   "residual_unit": "deg", "n_not_converged": int((~conv).sum()), "n_evaluations": n_eval[0],
                   "identifiable": identifiable, "at_bound": bool(at_bound),
                   "at_bound_parameters": ";".join(names[j] for j in at_bound)}
        log.info("calibration step %d (%s on %s): %s; rms ROM error %.4f deg, %d evaluations",
                 step, what, stage, params, summary["rms_residual"], n_eval[0])
        self.rom_fit.append(pd.DataFrame({"structure": what, "stage": stage, "direction": rows["direction"],
                                          "moment_nm": rows["moment_nm"], "rom_sim_deg": rom,
                                          "rom_mean_deg": target, "converged": conv}))
        return summary


def _final_fit(geometry, cal, base, published, reference, real_targets, info, family, transfer, spreads, *, level,
               k_shear, max_iter, geometry_path, final_surrogate_weight, tolerance_deg, real_fit_kw, row_influence=False):
    """The final joint step on the real rows: :func:`fit_admissible` (``transfer`` "elongation") or
    :func:`fit_real_targets`, started as the comments say; returns its fit and records it in ``info``."""
    # start of the final joint fit: the start set anchored on the real rows (step 0) with the fitted disc,
    # when the stepwise family contains it; the stepwise laws otherwise. On the short-fibre Visible Human
    # unit the stepwise fits drift (measured: knee shifts at their bounds, intact ROM 30-40 % off the
    # real rows), while the anchored set already meets the real rows: the joint fit then only trades it
    # against the surrogate stages (weight surrogate_weight) and the derived disc-only rows.
    final_start = cal
    if "anchor" in info and family == "scaled_published":
        final_start = replace_fields(base, name="calibrated", disc=cal.disc, absent=cal.absent, alternatives={})
        info["final_start"] = "start set anchored on the real rows (step 0)"
    else:
        info["final_start"] = "stepwise result"
    if transfer == "elongation":
        # the final set: the admissible fit again, with the fitted disc, from the step-0 optimum (the prior's
        # laws are its reference: scales and pre-elongation changes are relative to the prior)
        prior_set = replace_fields(info["prior_set"],
                                   disc=replace_fields(cal.disc, k_shear=info["prior_set"].disc.k_shear))
        a0 = info.get("anchor_fit")
        st = None if a0 is None else dict(zip(a0.parameters["parameter"], a0.parameters["fit_value"]))
        def refit(targets, start, **diag):
            return fit_admissible(geometry, prior_set, targets, level=level, published=published,
                                  geometry_path=geometry_path, k_shear=k_shear, max_iter=max_iter, start=start,
                                  prior_spread=spreads, disc_rows=stage_rows(reference, DISC_STAGE),
                                  **diag, **(real_fit_kw or {}))

        def refit_left_out(targets, start):
            # a diagnostic refit from the MAP: its table says whether it converged (influence.DIAGNOSTIC_MAX_NFEV)
            return refit(targets, start, diagnostic=True, max_nfev=influence.DIAGNOSTIC_MAX_NFEV)

        def refit_held(targets, start, stiffness):
            # the facet stiffness held at ``stiffness``: a prior of (numerically) zero width centred on it
            held = replace_fields(prior_set, facet=replace_fields(prior_set.facet, stiffness=stiffness))
            return fit_admissible(geometry, held, targets, level=level, published=published,
                                  geometry_path=geometry_path, k_shear=k_shear, max_iter=max_iter,
                                  start={**start, "facet_stiffness": math.log10(stiffness)},
                                  prior_spread={**(spreads or {}), "facet_stiffness": influence.HELD_LOG10_SD},
                                  disc_rows=stage_rows(reference, DISC_STAGE), diagnostic=True,
                                  max_nfev=influence.DIAGNOSTIC_MAX_NFEV, **(real_fit_kw or {}))

        def refit_spread(targets, start, spread):
            # the disc-only rows as data at a wider relative spread (a sensitivity refit from the MAP)
            return refit(targets, start, diagnostic=True, max_nfev=influence.DIAGNOSTIC_MAX_NFEV,
                         disc_data_sd_rel=spread)

        rf = refit(real_targets, st)
        info["final_fit"] = rf
        if row_influence:
            info["row_influence"] = pd.concat(
                [influence.row_influence(rf, real_targets, refit_left_out, geometry, level),
                 influence.facet_profile(rf, real_targets, refit_held, geometry, level),
                 influence.disc_spread_profile(rf, real_targets, refit_spread, geometry, level)], ignore_index=True)
    else:
        rf = fit_real_targets(geometry, final_start, real_targets, level=level, k_shear=k_shear,
                              max_iter=max_iter, secondary=reference if final_surrogate_weight > 0 else None,
                              secondary_weight=final_surrogate_weight or 1.0, tolerance_deg=tolerance_deg,
                              **(real_fit_kw or {}))
    return rf


def _facet_surface_rows(geometry, level):
    """Table 2 data: Eq. 4 coefficients per facet side, in mm."""
    surf_rows = []
    for side, _, s in facet_surfaces(geometry.levels[level]):
        p30, p03, p20, p02, p00 = s.coef
        # Eq. 4 in mm: f_mm = p30*1e-6 x_mm^3 + p03*1e-6 y^3 + p20*1e-3 x^2 + p02*1e-3 y^2 + p00*1e3
        for name, v, unit in (("p30", p30 * 1e-6, "1/mm^2"), ("p03", p03 * 1e-6, "1/mm^2"),
                              ("p20", p20 * 1e-3, "1/mm"), ("p02", p02 * 1e-3, "1/mm"), ("p00", p00 * 1e3, "mm")):
            surf_rows.append({"parameter": name, "side": side, "value": float(v), "unit": unit,
                              "rms_landmark_mm": s.rms_m * 1e3})
    return surf_rows


def calibrate(geometry, reference: pd.DataFrame, initial=None, level="L4-L5", k_shear=None,
              tolerance_deg=0.5, data_kind="surrogate", max_iter=50, tol=1e-7, max_nfev=60,
              start=None, concave=CONCAVE_CANDIDATES, surrogate_weight=1.0,
              real_targets: pd.DataFrame | None = None, real_fit_kw=None, family="monotone",
              anchor_start=True, final_surrogate_weight=0.0, transfer="strain", geometry_path=None,
              anchor_start_values: dict | None = None, prior="remus2021", row_influence=False) -> CalibrationResult:
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
    that stays slack; a structure whose fit ends where no ROM responds to it any more, e.g. a law moved to carry
    almost nothing, keeps its fitted value and is flagged not identifiable too) and ``at_bound`` (a fitted parameter
    within ``AT_BOUND_FRACTION`` of a bound).

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
    ``row_influence`` (elongation transfer only): also refit the final MAP without each real row in turn
    (:func:`.influence.row_influence`, ``info["row_influence"]``: what each row does to the judged internal loads).
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
    disc, disc_pts = _disc_step(base, reference, steps)
    # ---- steps 2-8: model with every calibrated ligament (start values); unfitted ones are masked by the stages
    cs, ligs, extra = _start_set(base, disc, family, start)
    fsu = build_fsu(geometry, cs, level, facet_stiffness_n_per_m=float(base.facet.stiffness), disc_shear_stiffness_n_per_m=k_shear)
    sw = _StepwiseFit(fsu, base, ligs, family, concave, tolerance_deg, surrogate_weight, max_iter, tol, max_nfev)
    for step, (what, stage) in enumerate(ORDER[1:], start=2):
        steps.append(sw.fit_structure(step, what, stage, reference))
    fitted, k_fac = sw.fitted, sw.k_fac
    # ---- final set
    final_ligs = {k: SoftplusLaw(*fitted[k], ligs[k].prestrain_pct, source=f"calibrated on {LIGAMENT_STAGE[k]}",
                                 law_length_m=ligs[k].law_length_m)
                  for k in CALIBRATED_LIGAMENTS}
    facet = replace_fields(base.facet, stiffness=k_fac)
    cal = replace_fields(cs, ligaments={**final_ligs, **extra}, facet=facet, alternatives={})
    if real_targets is not None and len(real_targets):
        rf = _final_fit(geometry, cal, base, published, reference, real_targets, info, family, transfer, spreads,
                        level=level, k_shear=k_shear, max_iter=max_iter, geometry_path=geometry_path,
                        final_surrogate_weight=final_surrogate_weight, tolerance_deg=tolerance_deg,
                        real_fit_kw=real_fit_kw, row_influence=row_influence)
        cal = replace_fields(rf.charset, name="calibrated", alternatives={})
        k_fac = float(cal.facet.stiffness)
        for kind_l in cal.ligaments:
            law = cal.ligaments[kind_l]
            fitted[kind_l] = (law.a, law.b, law.c, law.d)
        info["real_fit"] = rf.parameters
        info["real_fit_targets"] = rf.targets
        steps.append(_real_fit_step(rf, max(int(st["step"]) for st in steps) + 1, "real_targets", real_targets))
    return CalibrationResult(
        charset=cal, disc=dict(cal.disc.torque), facet_stiffness=k_fac, ligaments=fitted,
        summary=pd.DataFrame(steps), rom_fit=pd.concat(sw.rom_fit, ignore_index=True),
        disc_points=pd.DataFrame(disc_pts), ligament_points=pd.DataFrame(sw.lig_pts),
        facet_surfaces=pd.DataFrame(_facet_surface_rows(geometry, level)), data_kind=data_kind,
        wall_time_s=time.perf_counter() - t0, info=info)
