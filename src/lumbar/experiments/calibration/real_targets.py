"""The real-target fit: force scales of the passive structures (facet stiffness, disc shear stiffness, each
ligament's force) fitted so that the unit meets measured ROM rows (strain transfer of the ligament laws; the
calibration's step 0 and final step, and the surrogate generator's anchoring)."""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..fsu import build_fsu
from ..stepwise_reduction import StageSolver
from .common import AT_BOUND_FRACTION, IDENTIFIABLE_MIN_DEG, PENALTY, kind_groups, replace_fields, rom_widths

log = logging.getLogger(__name__)

#: parameters of the real-target fit: log10 scale factors of the facet contact stiffness, the disc shear
#: stiffness and the force of each ligament law (the law's shape, knee and prestrain are kept)
REAL_FIT_PARAMETERS = ("facet_stiffness", "disc_shear", "ALL", "PLL", "FL", "CL", "ISL", "SSL")
#: bounds of the log10 scales (decades) relative to the start set; the disc shear stiffness is instead
#: bounded by its sourced range (data/characteristics/disc.csv shear_stiffness_min/max)
FACET_STIFFNESS_RANGE = (1.0e3, 9.9e6)   # N/m, absolute bounds of the facet stiffness in the real-target fit
REAL_FIT_LOG10_BOUNDS = {"ALL": (-3.0, 1.0), "PLL": (-3.0, 1.0),
                         "FL": (-3.0, 1.0), "CL": (-3.0, 1.0), "ISL": (-3.0, 1.0), "SSL": (-3.0, 1.0)}


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
                ligs[name] = replace_fields(law, a=law.a * s, c=law.c * s)
            else:
                ligs[name] = replace_fields(law, f_a_n=law.f_a_n * s, f_b_n=law.f_b_n * s)
    facet = cs.facet
    if "facet_stiffness" in names:
        facet = replace_fields(facet, stiffness=float(facet.stiffness * scales[list(names).index("facet_stiffness")]))
    disc = replace_fields(cs.disc, k_shear=float(k_shear)) if k_shear is not None else cs.disc
    return replace_fields(cs, ligaments=ligs, facet=facet, disc=disc)


def _rows_and_scales(t, measured, secondary, secondary_weight, tolerance_deg):
    """(every fitted row, their measured ROM, their residual scales): the real rows ``t`` in units of 25 % of the
    measured value (the acceptance band of lumbar.experiments.validation), then the ``secondary`` rows that are not
    real rows, in units of their range (rows without a range: 2 x tolerance_deg)."""
    n_real = len(t)
    scale = 0.25 * measured / 1.0
    keys = ["stage", "direction", "moment_nm"]
    if secondary is not None and len(secondary):
        sec = secondary.reset_index(drop=True)
        sec = sec[~sec[keys].apply(tuple, axis=1).isin(set(t[keys].apply(tuple, axis=1)))].reset_index(drop=True)
        # weights: the secondary rows TOGETHER count secondary_weight times as much as the real rows together
        # (so 100 surrogate rows cannot outvote 4 measured ones)
        sw = rom_widths(sec, tolerance_deg) / math.sqrt(float(secondary_weight) * n_real / max(len(sec), 1))
        t_all = pd.concat([t[keys + ["rom_mean_deg"]], sec[keys + ["rom_mean_deg"]]], ignore_index=True)
        measured_all = t_all["rom_mean_deg"].to_numpy(float)
        scale = np.concatenate([scale, sw])
    else:
        t_all, measured_all = t, measured
    return t_all, measured_all, scale


def _parameter_vector(charset, parameters, ks0):
    """(names, lower bounds, upper bounds, start) of the fit vector: log10 scales of ``parameters`` present in
    ``charset`` (the disc shear stiffness as log10 of its value, within its sourced range)."""
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
    return names, lo, hi, x0


def _parameter_rows(charset, cs, names, q, x0, lo, hi, scales, ks, sens, free, at_bound):
    """One row per fit parameter of :attr:`RealFit.parameters` (start, value, bounds in the parameter's unit)."""
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
    return rows


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
    from scipy.optimize import least_squares  # noqa: PLC0415 - scipy.optimize (about a second) only where a fit runs
    t = targets.reset_index(drop=True)
    if t.empty:
        raise ValueError("fit_real_targets: no target rows")
    measured = t["rom_mean_deg"].to_numpy(float)
    if not np.all(np.isfinite(measured) & (measured > 0)):
        raise ValueError("fit_real_targets: every target rom_mean_deg must be finite and > 0 deg")
    n_real = len(t)
    t_all, measured_all, scale = _rows_and_scales(t, measured, secondary, secondary_weight, tolerance_deg)
    ks0 = float(k_shear if k_shear is not None else charset.disc.k_shear)
    names, lo, hi, x0 = _parameter_vector(charset, parameters, ks0)
    fsu = build_fsu(geometry, charset, level, disc_shear_stiffness_n_per_m=ks0)
    m = fsu.model
    par_scale0, k_fac0 = m.f_scale.copy(), m.facet_stiffness()
    groups = {k: np.isin(m.f_group, kind_groups(m, k)) for k in names}
    ss = StageSolver(fsu, t_all[["stage", "direction", "moment_nm"]], max_iter=max_iter, tol=tol)
    n_eval = [0]

    def apply(q):
        m.f_scale[:] = par_scale0
        m.set_facet_stiffness(k_fac0[m.k_surf])
        for name, v in zip(names, q):
            if name == "facet_stiffness":
                m.set_facet_stiffness(k_fac0[m.k_surf] * 10.0 ** v)
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
    rows = _parameter_rows(charset, cs, names, q, x0, lo, hi, scales, ks, sens, free, at_bound)
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
