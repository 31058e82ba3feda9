"""The admissible fit: a MAP estimate of the characteristic set on real ROM rows, the derived disc-only rows and the
physical-admissibility criteria (one-sided penalties), with sourced priors and its Laplace posterior; the rows it is
pinned to, one parameter moved in fit units (the posterior bands), its posterior tables and the documented reasons
for parameters at a bound."""
from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ...inputs.characteristics import load_characteristic_set
from .. import admissibility as ADM
from ..fsu import MIN_SLACK_FRACTION, build_fsu, set_ligament_law
from ..posterior import Posterior, covariance_table, laplace_posterior, posterior_table
from ..priors import DISC_CURVE_LOG10_SD, default_spreads, prior_sources
from .common import AT_BOUND_FRACTION, PENALTY
from .disc import eq3
from .penalties import FIT_MARGIN, fit_penalties, scale_penalties
from .probe import Probe, rom_of
from .real_targets import FACET_STIFFNESS_RANGE, RealFit

log = logging.getLogger(__name__)

PENALTY_WEIGHT = 3.0
#: spread of a real ROM row when its source gives none (Yamamoto et al. 1989's abstract gives means only): 25 % of the
#: measured value, the validation's acceptance band (an assumption, stated in the posterior table, role calibration.posterior)
DATA_SD_REL = 0.25
#: least-squares budget and tolerance (x, f and gradient) of the MAP fit: at 100 evaluations and 1e-6 the default fit
#: stopped at max_nfev (first-order optimality 0.3); 400 and 1e-8 converge it (measured ~175 evaluations, optimality
#: 1e-3; the MAP moved by < 0.1 prior spreads)
MAX_NFEV = 400
FIT_TOL = 1e-8
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


@dataclass
class AdmissibleFit(RealFit):
    """:class:`RealFit` of :func:`fit_admissible` plus its last probe (metrics at the fitted set) and penalties."""

    probe: dict = field(default_factory=dict)
    penalties: pd.DataFrame | None = None
    prior: object = None
    posterior: Posterior | None = None
    objective: object = None
    #: the optimizer's verdict: status, message, nfev, first-order optimality, converged (status > 0: a tolerance
    #: met; 0: max_nfev reached before any tolerance, the MAP is not converged and the results say so)
    optimizer: dict = field(default_factory=dict)


def set_with(charset, names, q):
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
        return set_with(charset, [name], [math.log10(charset.facet.stiffness) + delta])
    if name == "disc_shear":
        return set_with(charset, [name], [math.log10(charset.disc.k_shear) + delta])
    return set_with(charset, [name], [delta])


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


def _parameter_vector(lev, charset, ks0, fit_disc_torque):
    """(names, lower bounds, upper bounds, prior centre) of the admissible fit's vector on level geometry ``lev``
    (fit units: log10 force scales, pre-elongation changes [mm], log10 stiffnesses, log10 disc torque scales)."""
    names, lo, hi, x0 = [], [], [], []
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
    return names, np.array(lo), np.array(hi), np.array(x0)


class _Objective:
    """The admissible fit's stacked residuals at a fit vector ``q`` and their Jacobian (finite differences of the
    probe's linearised equilibria); keeps the last converged evaluation in :attr:`last` (q, metrics ``mt``,
    penalties ``pen``, residuals ``r``) and counts residual and linearised evaluations in :attr:`n_eval`."""

    def __init__(self, probe, base, names, hi, prior_q, prior_sd, limit, nz, directions, measured, dr, torque,
                 data_sd_rel, disc_sd_rel=None):
        self.probe, self.base, self.names, self.hi = probe, base, names, hi
        self.prior_q, self.prior_sd, self.limit, self.nz = prior_q, prior_sd, limit, nz
        self.directions, self.measured, self.dr, self.torque = directions, measured, dr, torque
        self.data_sd_rel = data_sd_rel
        # spread of the disc-only curve as data for this unit (default: that of a measured row)
        self.disc_sd_rel = data_sd_rel if disc_sd_rel is None else disc_sd_rel
        # the disc-only rows of one direction are points of one published curve (derived from the paper's Eq. 3
        # fit), not independent measurements: together they count as one observation of spread data_sd_rel (each
        # row's residual divided by sqrt(rows of its direction)); counted as independent rows they would pin the
        # disc torque scale sqrt(n) times tighter than the one curve they come from
        n_dir = {}
        for d, _, _ in dr:
            n_dir[d] = n_dir.get(d, 0) + 1
        self.dr_weight = np.array([1.0 / math.sqrt(n_dir[d]) for d, _, _ in dr])
        m = probe.fsu.model
        self.groups = {k: [g for g, (_, kk, _lv) in enumerate(m.fibre_groups) if kk == k] for k in base.ligaments}
        self.fibres = {k: np.flatnonzero(np.isin(m.f_group, g)) for k, g in self.groups.items()}
        self.applied = {}        # kind -> the law last written into the model (a Jacobian column changes one)
        # the fit vector's entries per part of the set (a ligament kind, the facets, the disc), in the vector's order:
        # set_with on a part's entries alone gives that part as set_with on the whole vector does
        parts: dict = {}
        for j, n in enumerate(names):
            kind = n.split(":")[0]
            part = kind if kind in base.ligaments else ("facet" if n == "facet_stiffness" else "disc")
            parts.setdefault(part, []).append(j)
        self.parts = {k: np.array(v) for k, v in parts.items()}
        self.part_cache = {}     # part -> (its entries of q, the set_with made of them): the last one
        self.disc_cache = None   # (disc torque scales, disc_residuals, disc_reach): the last ones
        self.torque_idx = {n.split(":")[1]: j for j, n in enumerate(names) if n.startswith("disc_torque:")}
        self.n_eval = [0, 0]
        self.n_res = None        # length of a residual vector (a failed probe returns one of the same length)
        self.last = {}

    def _part(self, part, q):
        """The set made by ``q``'s entries of ``part`` alone (:func:`set_with`), kept for the next call: a Jacobian
        column changes one entry, so every other part is the one made before."""
        idx = self.parts.get(part)
        if idx is None:
            return self.base
        v = tuple(float(x) for x in np.asarray(q, float)[idx])
        hit = self.part_cache.get(part)
        if hit is None or hit[0] != v:
            hit = (v, set_with(self.base, [self.names[j] for j in idx], v))
            self.part_cache[part] = hit
        return hit[1]

    def apply(self, q):
        """Write the set at ``q`` (that of ``set_with(base, names, q)``) into the probe's model."""
        m = self.probe.fsu.model
        for kind in self.base.ligaments:
            law = self._part(kind, q).ligaments[kind]
            if hasattr(law, "a") and self.groups.get(kind) and self.applied.get(kind) != law:
                set_ligament_law(m, self.groups[kind], law, sel=self.fibres[kind])
                self.applied[kind] = law
        m.set_facet_stiffness(self._part("facet", q).facet.stiffness)
        disc = self._part("disc", q).disc
        for d in m.discs:
            d.k_shear = disc.k_shear
            d.torque = dict(disc.torque)

    def disc_residuals(self, q):
        """The disc-only rows in torque space at the measured angle (Eq. 3 as step 1 fits it)."""
        out = []
        for d, M, phi in self.dr:
            p1, p2, p3 = self.torque[d]
            sc = 10.0 ** q[self.torque_idx[d]] if d in self.torque_idx else 1.0
            out.append((float(eq3(phi, (p1 * sc, p2, p3 * sc))) - M) / (self.disc_sd_rel * M))
        return np.array(out) * self.dr_weight

    def reach_directions(self):
        """(direction, largest moment [N*m], largest angle [rad]) of the disc-only rows per direction."""
        out = {}
        for d, M, phi in self.dr:
            m0, p0 = out.get(d, (0.0, 0.0))
            out[d] = (max(m0, M), max(p0, phi))
        return [(d, m, p) for d, (m, p) in out.items()]

    def disc_reach(self, q):
        """One-sided constraint per direction: the scaled disc law reaches the largest disc-only moment within 1.5 x
        its measured angle (a law whose torque peaks below it has no disc-only equilibrium there: the paper's
        flexion law has p3 < 0 and peaks near its 10 N*m row, so a scale below 1 would remove that equilibrium,
        which the torque-space residual at the measured angle does not see)."""
        out = []
        for d, M, phi in self.reach_directions():
            p1, p2, p3 = self.torque[d]
            sc = 10.0 ** q[self.torque_idx[d]] if d in self.torque_idx else 1.0
            grid = np.linspace(0.0, 1.5 * phi, 301)
            peak = float(np.max(eq3(grid, (p1 * sc, p2, p3 * sc))))
            out.append(max(0.0, 1.02 * M - peak) / (0.05 * M))
        return np.array(out)

    def from_metrics(self, q, mt):
        """(stacked residuals, penalties) at ``q`` from the probe metrics ``mt``."""
        pen = fit_penalties(mt, self.limit, self.nz) + scale_penalties(self.names, q, mt)
        rel = (rom_of(mt, self.directions) - self.measured) / self.measured
        edge = np.maximum(0.0, np.abs(rel) - FIT_MARGIN["rom_rel"]) / 0.05
        key = tuple(float(q[j]) for j in self.torque_idx.values())   # both read only the disc torque scales
        if self.disc_cache is None or self.disc_cache[0] != key:
            self.disc_cache = (key, self.disc_residuals(q), self.disc_reach(q))
        _, disc_r, reach = self.disc_cache
        return np.concatenate([rel / self.data_sd_rel, disc_r, PENALTY_WEIGHT * edge,
                               PENALTY_WEIGHT * reach,
                               PENALTY_WEIGHT * np.array([v for _, v in pen]),
                               (q - self.prior_q) / self.prior_sd]), pen

    def residual_names(self, pen):
        """Names of the stacked residuals, in order."""
        return [f"ROM {d} (data)" for d in self.directions] + \
            [f"disc-only {d} {M:g} N*m (data)" for d, M, _ in self.dr] + \
            [f"ROM {d} (25 % band constraint)" for d in self.directions] + \
            [f"disc-only {d} reaches {M:g} N*m (constraint)" for d, M, _ in self.reach_directions()] + \
            [n for n, _ in pen] + \
            [f"prior {n}" for n in self.names]

    def residual(self, q):
        """The stacked residuals at ``q`` (PENALTY everywhere where the probe finds no equilibrium)."""
        self.apply(q)
        self.n_eval[0] += 1
        x, R, ok = self.probe.run()
        if not ok:
            self.last.clear()
            n = 2 * len(self.measured) + len(self.dr) + len(self.reach_directions()) + 40 + len(q)
            return np.full(self.n_res or n, PENALTY)
        mt = self.probe.metrics(x, R)
        r, pen = self.from_metrics(q, mt)
        self.n_res = len(r)
        self.last.update(q=np.array(q), mt=mt, pen=pen, r=r)
        return r

    def jacobian(self, q):
        """Finite differences of the linearised equilibria, one Newton step per parameter."""
        last, probe = self.last, self.probe
        if last.get("q") is None or not np.array_equal(last["q"], q) or probe.state is None:
            self.residual(q)
        if probe.state is None:
            return np.zeros((len(last.get("r", np.zeros(1))), len(q)))
        r0 = last["r"]
        Jm = np.empty((len(r0), len(q)))
        for j in range(len(q)):
            h = 1e-4 * max(1.0, abs(q[j]))
            h = -h if q[j] + h > self.hi[j] else h
            qj = np.array(q, float)
            qj[j] += h
            self.apply(qj)
            self.n_eval[1] += 1
            x, R = probe.linearised()
            Jm[:, j] = (self.from_metrics(qj, probe.metrics(x, R))[0] - r0) / h
        self.apply(q)
        return Jm


def _start_scan(obj, names, prior_q, lo, hi):
    """The best of a one-dimensional scan of one common force scale of every ligament (START_SCALES; the prior laws
    are an order of magnitude too stiff or too soft on a geometry they were not calibrated on)."""
    best = None
    for s_ in START_SCALES:
        q_try = prior_q.copy()
        q_try[[j for j, n in enumerate(names) if n.endswith(":scale")]] = math.log10(s_)
        q_try = np.clip(q_try, lo, hi)
        obj.probe.warm = None
        r_try = obj.residual(q_try)
        cost_try = float(r_try @ r_try)
        if best is None or cost_try < best[0]:
            best = (cost_try, q_try)
    return best[1]


def _parameter_rows(names, q, prior_q, lo, hi):
    """One row per fit parameter of :attr:`AdmissibleFit.parameters` (value and bounds in the parameter's unit,
    the fit value, at-bound flag and its documented reason)."""
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
    return rows


def fit_admissible(geometry, charset, targets: pd.DataFrame, level="L4-L5", published=None, geometry_path=None,
                   k_shear=None, max_iter=50, tol=1e-8, max_nfev=MAX_NFEV,
                   nz_reference=None, start: dict | None = None, prior_spread: dict | None = None,
                   data_sd_rel: float = DATA_SD_REL, fit_disc_torque: bool = True,
                   disc_rows: pd.DataFrame | None = None, diagnostic: bool = False,
                   disc_data_sd_rel: float | None = None) -> AdmissibleFit:
    """Fit a characteristic set to real ROM rows AND the admissibility criteria (constrained least squares).

    ``disc_data_sd_rel``: the relative spread of the disc-only rows as data for this unit (default ``data_sd_rel``):
    how far the disc of the specimens behind the disc-only curve (Heuer et al. 2007) may differ from this unit's; a
    sensitivity refit (:func:`.influence.disc_spread_profile`) widens it.

    ``diagnostic``: a refit that only feeds a diagnostic table (leave one row out, a held parameter, a wider disc-only
    spread) or anchors the virtual specimens of the surrogate generator, whose table records whether it converged
    (``converged`` / ``map_converged``): its non-convergence is logged at INFO, not as a WARNING for the user. The
    shipped calibration's own MAP is never diagnostic.

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
    measured); the disc-only rows of one direction, points of one published curve, together as one observation
    (each divided by the square root of their number). The minimum is a MAP estimate (penalties = soft constraints); its Laplace posterior (the Gauss-Newton
    Hessian of the same stacked residuals at the optimum) is :attr:`AdmissibleFit.posterior`. The Jacobian is finite
    differences of the linearised equilibria (one Newton step per parameter, :class:`.probe.Probe`). ``start``: {parameter
    name: value in fit units} to start from (e.g. a previous fit). The admissibility of the result is checked
    afterwards on 0.25 N*m curves (:func:`admissibility.evaluate`).
    """
    from scipy.optimize import least_squares  # noqa: PLC0415 - scipy.optimize (about a second) only where a fit runs
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
    names, lo, hi, prior_q = _parameter_vector(geometry.levels[level], charset, ks0, fit_disc_torque)
    if np.any(lo >= hi):
        bad = [n for n, a, b in zip(names, lo, hi) if a >= b]
        raise ValueError(f"fit_admissible: empty parameter range for {bad} (the prior law leaves no admissible "
                         "pre-elongation on this level's fibres)")
    # the prior centre may lie outside a physical bound (e.g. a prior pre-elongation beyond what this level's shortest
    # fibre allows): the fit starts inside the bounds and the prior term still pulls toward the centre
    q_start = np.clip(prior_q, lo, hi)
    for j, n in enumerate(names):
        if start and n in start and np.isfinite(start[n]):
            q_start[j] = float(np.clip(start[n], lo[j], hi[j]))
    base = charset if k_shear is None else dataclasses.replace(
        charset, disc=dataclasses.replace(charset.disc, k_shear=ks0))
    fsu = build_fsu(geometry, base, level, follower=True)
    probe = Probe(fsu, max_iter=max_iter, tol=tol)
    if geometry_path is not None:
        from ...geometry.visible_human import read_uw_materials  # noqa: PLC0415
        probe.set_remus(read_uw_materials(geometry_path, level))
    directions = list(t["direction"])
    # the disc-only rows (the stage the disc law was fitted on) as data too, in torque space at the measured angle
    # (Eq. 3 as step 1 fits it): the disc torque scales are then informed by their own data, and their prior, centred
    # on the same curve, must not count it again (priors.DISC_TORQUE_LOG10_SD); a direction without rows keeps the
    # curve as its prior (priors.DISC_CURVE_LOG10_SD)
    dr = [] if disc_rows is None or not fit_disc_torque else \
        [(str(r.direction), float(r.moment_nm), math.radians(float(r.rom_mean_deg)))
         for r in disc_rows.itertuples(index=False) if str(r.direction) in charset.disc.torque]
    defaults = default_spreads(names, lo, hi, disc_data_directions={d for d, _, _ in dr})
    prior_sd = np.array([(prior_spread or {}).get(n, d) for n, d in zip(names, defaults)], float)
    if np.any(~np.isfinite(prior_sd)) or np.any(prior_sd <= 0):
        raise ValueError(f"fit_admissible: every prior spread must be finite and > 0, got {dict(zip(names, prior_sd))}")
    obj = _Objective(probe, base, names, hi, prior_q, prior_sd, limit, nz, directions, measured, dr,
                     charset.disc.torque, data_sd_rel, disc_data_sd_rel)
    if not start:         # no start given: the best common force scale of every ligament
        q_start = _start_scan(obj, names, prior_q, lo, hi)
        probe.warm = None
    r_start = obj.residual(q_start)
    sol = least_squares(obj.residual, q_start, jac=obj.jacobian, method="trf", bounds=(lo, hi), x_scale=0.3,
                        xtol=FIT_TOL, ftol=FIT_TOL, gtol=FIT_TOL, max_nfev=max_nfev)
    optimizer = {"status": int(sol.status), "message": str(sol.message), "nfev": int(sol.nfev),
                 "optimality": float(sol.optimality), "converged": bool(sol.status > 0)}
    if not optimizer["converged"]:
        (log.info if diagnostic else log.warning)("admissible fit NOT converged: %s after %d evaluations (first-order optimality %.3g); the MAP "
                    "and its posterior are those of the last iterate (the posterior table, role calibration.posterior, "
                    "column map_converged)", sol.message, sol.nfev, sol.optimality)
    q = sol.x
    obj.residual(q)
    last = obj.last
    if not last:
        raise RuntimeError("fit_admissible: the fitted set has no equilibrium in every probe scenario")
    J_map = obj.jacobian(q)
    obj.residual(q)
    post = laplace_posterior(names, q, prior_q, prior_sd, lo, hi, J_map, last["r"], obj.residual_names(last["pen"]),
                             n_data=len(measured) + len(dr))
    cs = set_with(base, names, q)
    cs = dataclasses.replace(cs, ligaments={k: dataclasses.replace(v, source="calibrated on elongation (fit_admissible)")
                                            for k, v in cs.ligaments.items()})
    mt = last["mt"]
    rom = rom_of(mt, directions)
    rows = _parameter_rows(names, q, prior_q, lo, hi)
    tt = t[["stage", "direction", "moment_nm", "rom_mean_deg"]].copy()
    tt["rom_sim_deg"] = rom
    tt["rel_error"] = (rom - measured) / measured
    tt["converged"] = True
    pen = pd.DataFrame([{"penalty": n, "value": v} for n, v in last["pen"]])
    log.info("admissible fit: %d residual and %d linearised evaluations, cost %.4g -> %.4g; ROM %s deg; active "
             "penalties: %s", obj.n_eval[0], obj.n_eval[1], 0.5 * float(r_start @ r_start), float(sol.cost),
             np.round(rom, 2).tolist(), ", ".join(f"{n} {v:.2g}" for n, v in last["pen"] if v > 0) or "none")
    fit = AdmissibleFit(cs, pd.DataFrame(rows), tt, float(sol.cost), obj.n_eval[0], probe=mt, penalties=pen,
                        prior=charset, posterior=post, optimizer=optimizer)
    fit.objective = obj.residual      # q (fit units) -> the stacked residuals: for a sampling check of the posterior
    return fit


POSTERIOR_COLUMNS = ("parameter", "unit", "fit_unit", "prior_centre", "prior_90_low", "prior_90_high",
                     "prior_centre_fit", "prior_spread_fit", "map", "posterior_90_low", "posterior_90_high", "map_fit",
                     "posterior_spread_fit", "spread_ratio", "shift_prior_sd", "moved_by", "data_moved_it", "at_bound",
                     "bound_reason", "prior_source", "prior", "data_spread", "map_converged")


def posterior_tables(fit: AdmissibleFit | None, prior_name: str = "") -> tuple[pd.DataFrame, pd.DataFrame]:
    """(posterior, posterior covariance: roles calibration.posterior and calibration.covariance) of the final admissible fit: per parameter the
    prior (centre, spread, source), the MAP, the Laplace 90 % interval, posterior/prior spread, which rows moved it
    and the at-bound flag with its reason (:func:`lumbar.experiments.posterior.posterior_table`); empty tables with
    the columns when there was no admissible fit (a strain-transfer calibration)."""
    if fit is None or fit.posterior is None:
        return pd.DataFrame(columns=list(POSTERIOR_COLUMNS)), \
            pd.DataFrame(columns=["parameter_i", "parameter_j", "covariance"])
    post = fit.posterior
    src = prior_sources(post.names, prior_name or "table3")
    for j, n in enumerate(post.names):
        if n.startswith("disc_torque:"):
            as_data = float(np.asarray(post.prior_sd)[j]) > 2.0 * DISC_CURVE_LOG10_SD
            src[n] = ("centre: the disc-only fit (step 1, Eq. 3 on the disc-only rows); spread: " +
                      ("one decade, because the same rows enter the likelihood as data (one observation per "
                       f"direction, spread {DATA_SD_REL:.0%} assumed: no specimen spread published) and are counted "
                       "once" if as_data else
                       f"that of a measured row, {DATA_SD_REL:.0%} (assumed: no specimen spread published; the "
                       "disc-only rows are not in this fit's likelihood)"))
    tab = posterior_table(post, src, BOUND_REASONS).assign(
        prior=prior_name, data_spread=f"{DATA_SD_REL:.0%} of each measured ROM row (assumed; none published)",
        map_converged=bool(fit.optimizer.get("converged", True)))
    return tab[list(POSTERIOR_COLUMNS)], covariance_table(post)


def read_fit_start(path) -> dict | None:
    """{parameter: fit value} of a :func:`fit_admissible` parameter table (e.g. the surrogate generator's anchoring,
    role virtual_experiment.generator_fit of the stage manifests), to start another fit from; None when the file is
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
    "CL:pre_elongation": "the upper bound is the prestrain cap MAX_PRESTRAIN_PCT (2.5 x the largest prestrain of paper "
                         "1, Sect. 2.2.4), a limit of the model's validity, not a value the data chose: the fit presses "
                         "the capsules' pre-tension against it when the ROM rows ask for more stiffness than the other "
                         "structures give within their priors (the rows that pushed it: column moved_by; on the "
                         "morphable lumbar mean, the axial-rotation row, as for the facet stiffness; docs/specimen.md)",
    "facet_stiffness": "the facet contact acts as a stiff pivot (cartilage contact); the ROM does not change between "
                       "1e6 and 1e7 N/m (docs/validity.md)",
}
