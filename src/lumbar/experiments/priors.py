"""Sourced priors of the calibration's parameters (centre and spread), for the MAP fit of
:func:`lumbar.experiments.calibration.fit_admissible`.

Every fitted parameter of the calibrated unit gets a prior from a source, so that what the data (four intact range-of-
motion values and the admissibility criteria) cannot move stays where a source put it, and the results say so
(the posterior table, role ``calibration.posterior`` of the stage manifests):

- **ligament laws** (``prior: remus2021``, the default): the Remus et al. (2021) calibration of *the same fibres*
  (the ``*_UWMat.lig`` files of the embedded Visible Human set; Blankevoort/UW law per fibre), expressed as the
  project's Eq. 7 law on elongation (:func:`remus_as_softplus`): force scale 1 and pre-elongation change 0 are the
  Remus ligament. ``prior: table3``: paper 1 Table 3 on elongation (the Rupp et al. 2015 law where Table 3 has none,
  as for the ITL and the concave flavum; :func:`lumbar.experiments.calibration.elongation_prior`).
- **spreads of the ligament parameters**: how much two independent, sourced calibrations of the same ligament
  disagree on this geometry (:func:`source_disagreement`): the root-mean-square over the ligament kinds of the log10
  ratio of the two laws' forces at a common elongation (force scale) and of their pre-elongations (mm). Two
  published calibrations of the same structures differing by this much is the uncertainty a modeller has before
  seeing the data; ``derived_from_published_fit``.
- **facet contact stiffness**: paper 1 Sect. 2.2.3 (12,000 N/m), log10 spread :data:`FACET_LOG10_SD` (documented:
  the paper's value belongs to its own contact discretisation, a cubic surface with one contact per landmark, so it
  is an order of magnitude, not a measurement of this unit's contact points).
- **disc shear stiffness**: the sourced motion-segment range (``data/characteristics/disc.csv``, 53-140 N/mm): its
  geometric mean as centre and the range as +-2 spreads (a 95 % interval) in log10.

A prior is a *centre and a spread*, never a bound: the bounds of the fit stay the physical ones (a fibre keeps a
slack length, a stiffness stays positive).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd

from ..inputs.characteristics import SoftplusLaw

#: log10 spread of the facet contact stiffness prior (paper 1's value is its own contact model's; documented)
FACET_LOG10_SD = 1.0
#: elongation range [m] over which a Remus law is expressed as Eq. 7 (beyond each fibre's slack length)
REMUS_FIT_ELONGATION_M = 6e-3
#: smallest spreads: a force scale within a factor 1.5 (log10 0.18) and a pre-elongation within 0.25 mm are treated as
#: equally well sourced, so that two sources that happen to agree do not make a prior the data cannot move
MIN_SCALE_LOG10_SD = 0.3
MIN_PRE_ELONGATION_SD_MM = 0.5
#: elongations [m] beyond slack at which two sources' laws are compared (where a ligament works at 10 N*m)
COMPARE_ELONGATIONS_M = (2e-3, 4e-3, 6e-3)
PRIORS = ("remus2021", "table3")


def _softplus_zero(eps_pct, a, b, d):
    return a * (np.logaddexp(0.0, (np.asarray(eps_pct, float) + b) / d) - np.logaddexp(0.0, b / d))


def remus_group_force(lengths_m, materials: dict, elongation_m) -> np.ndarray:
    """Force [N] of one ligament group of the Remus et al. (2021) model (UW law per fibre, summed over the fibres of
    the group) when every fibre is stretched by ``elongation_m`` (k,) beyond its own slack length
    l0 = l_geometric (1 + reference strain)."""
    L = np.asarray(lengths_m, float)
    l0 = L * (1.0 + materials["reference_strain"])
    e = np.asarray(elongation_m, float)[:, None] / l0[None, :]
    et, k = materials["transition_strain"], materials["stiffness_n"]
    f = np.where(e <= 0, 0.0, np.where(e < et, k * e * e / (2.0 * et), k * (e - 0.5 * et)))
    return f.sum(axis=1)


def remus_as_softplus(groups, materials: dict, n: int = 241):
    """The Remus et al. (2021) law of one ligament kind on this level's fibres as the project's Eq. 7 law on
    elongation (one law per fibre group, as the model applies it: every group of the kind carries the law's force).

    ``groups``: [(group name, (n_i,) fibre lengths [m])] of the kind at the level; ``materials``: the level's
    :func:`lumbar.geometry.visible_human.read_uw_materials`. Returns (SoftplusLaw with ``law_length_m`` = the
    fibres' mean Remus slack length and the prestrain that gives the fibres' mean Remus pre-elongation, provenance
    dict with the largest deviation of the Eq. 7 fit [N])."""
    from scipy.optimize import least_squares  # noqa: PLC0415 - scipy.optimize (about a second) only where a fit runs
    used = [(name, L) for name, L in groups if name in materials]
    if not used:
        raise ValueError(f"no Remus et al. (2021) material for the fibre groups {[g for g, _ in groups]}")
    e = np.linspace(0.0, REMUS_FIT_ELONGATION_M, n)
    F = np.mean([remus_group_force(L, materials[name], e) for name, L in used], axis=0)
    l0 = np.concatenate([np.asarray(L, float) * (1.0 + materials[name]["reference_strain"]) for name, L in used])
    lg = np.concatenate([np.asarray(L, float) for name, L in used])
    law_length = float(l0.mean())
    pre_elong = float((lg - l0).mean())            # > 0: pre-stretched at rest (negative reference strain)
    eps = 100.0 * e / law_length
    scale = max(float(F.max()), 1e-6)
    sol = least_squares(lambda q: (_softplus_zero(eps, q[0], q[1], q[2]) - F) / scale, [F.max() / 10, -5.0, 2.0],
                        bounds=([1e-3, -80.0, 0.05], [1e5, 40.0, 80.0]), xtol=1e-12, ftol=1e-12)
    a, b, d = (float(v) for v in sol.x)
    c = -a * float(np.logaddexp(0.0, b / d))
    err = float(np.abs(_softplus_zero(eps, a, b, d) - F).max())
    law = SoftplusLaw(a, b, c, d, 100.0 * pre_elong / law_length,
                      source="prior: Remus et al. (2021) UW law of the same fibres, as Eq. 7 on elongation",
                      law_length_m=law_length)
    return law, {"fit_max_deviation_n": err, "force_at_fit_end_n": float(F[-1]),
                 "reference_strain": float(np.mean([materials[nm]["reference_strain"] for nm, _ in used]))}


def level_fibre_groups(level_geom, kind):
    """[(group name, (n,) fibre lengths [m])] of a ligament kind at a geometry level (straight length plus the
    via-point extra length)."""
    out = []
    for lig in level_geom.ligaments:
        if lig.kind == kind:
            L = np.linalg.norm(np.asarray(lig.upper, float) - np.asarray(lig.lower, float), axis=1) + \
                np.broadcast_to(np.asarray(lig.extra_length, float), (len(lig.upper),))
            out.append((lig.name, L))
    return out


def remus_prior(base, level_geom, materials: dict, kinds):
    """(CharacteristicSet ``base`` with the ligaments of ``kinds`` replaced by :func:`remus_as_softplus`, provenance
    table: ligament, a_n, b_pct, c_n, d_pct, prestrain_pct, law_length_mm, pre_elongation_mm, source, note)."""
    ligs, rows = dict(base.ligaments), []
    for kind in kinds:
        law, info = remus_as_softplus(level_fibre_groups(level_geom, kind), materials)
        ligs[kind] = law
        rows.append({"ligament": kind, "a_n": law.a, "b_pct": law.b, "c_n": law.c, "d_pct": law.d,
                     "prestrain_pct": law.prestrain_pct, "law_length_mm": law.law_length_m * 1e3,
                     "pre_elongation_mm": law.pre_elongation_m * 1e3,
                     "source": "Remus et al. (2021), PLoS ONE 16(4):e0250456: UW law of the same fibres "
                               "(data/geometry/visible_human_lss/ligaments/*_UWMat.lig)",
                     "note": f"Eq. 7 on elongation fitted over 0-{REMUS_FIT_ELONGATION_M * 1e3:g} mm beyond slack, "
                             f"largest deviation {info['fit_max_deviation_n']:.2g} N of "
                             f"{info['force_at_fit_end_n']:.3g} N"})
    cs = dataclasses.replace(base, name="calibrated", ligaments=ligs,
                             source="Remus et al. (2021) prior (lumbar.experiments.priors.remus_prior)")
    return cs, pd.DataFrame(rows)


def law_force(law, elongation_m):
    """Force [N] of a softplus law on elongation at ``elongation_m`` beyond its slack length."""
    eps = 100.0 * np.asarray(elongation_m, float) / law.law_length_m
    return law.a * np.logaddexp(0.0, (eps + law.b) / law.d) + law.c


def source_disagreement(law_a: dict, law_b: dict, elongations_m=COMPARE_ELONGATIONS_M) -> pd.DataFrame:
    """Per ligament kind present in both ``{kind: SoftplusLaw on elongation}`` maps: the log10 ratio of the two
    laws' forces (mean over ``elongations_m`` beyond slack) and the difference of their pre-elongations [mm]. The
    spreads of the ligament priors are the root-mean-square of these over the kinds (:func:`ligament_spreads`)."""
    rows = []
    for k in sorted(set(law_a) & set(law_b)):
        a, b = law_a[k], law_b[k]
        if not (hasattr(a, "a") and hasattr(b, "a")) or a.law_length_m is None or b.law_length_m is None:
            continue
        fa = np.maximum(law_force(a, elongations_m), 1e-6)
        fb = np.maximum(law_force(b, elongations_m), 1e-6)
        rows.append({"ligament": k, "log10_force_ratio": float(np.mean(np.log10(fa / fb))),
                     "pre_elongation_difference_mm": float((a.pre_elongation_m - b.pre_elongation_m) * 1e3)})
    return pd.DataFrame(rows)


#: ligament kinds whose second source (paper 1 Table 3 on elongation) is not a calibration of real data: the ITL
#: (no Table 3 row; the Rupp et al. 2015 law, which the paper calls non-validated, Sects. 2.2.4, 4.3) and the FL (its
#: Table 3 law is concave, the paper attributes it to the vertebral-arch artefact; the Rupp law stands in). Their
#: disagreement measures no calibration uncertainty: their spread is the median of the calibrated kinds'
UNCALIBRATED_SECOND_SOURCE = ("ITL", "FL")


def ligament_spreads(disagreement: pd.DataFrame) -> dict:
    """{fit parameter name: prior spread (fit units)} of every ligament kind in ``disagreement``
    (:func:`source_disagreement`): the force scale's log10 spread is the kind's own |log10 ratio| of the two sourced
    laws, the pre-elongation's the kind's own |difference| [mm], floored at :data:`MIN_SCALE_LOG10_SD` and
    :data:`MIN_PRE_ELONGATION_SD_MM`. Where two independent calibrations of the same fibres agree the prior is
    narrow; where they disagree by an order of magnitude, so does the prior."""
    out = {}
    cal = disagreement[~disagreement["ligament"].isin(UNCALIBRATED_SECOND_SOURCE)]
    med_s = float(np.median(np.abs(cal["log10_force_ratio"]))) if len(cal) else DEFAULT_SCALE_LOG10_SD
    med_p = float(np.median(np.abs(cal["pre_elongation_difference_mm"]))) if len(cal) else \
        DEFAULT_PRE_ELONGATION_SD_MM
    for r in disagreement.itertuples():
        own = r.ligament not in UNCALIBRATED_SECOND_SOURCE
        s_ = abs(float(r.log10_force_ratio)) if own else med_s
        p_ = abs(float(r.pre_elongation_difference_mm)) if own else med_p
        out[f"{r.ligament}:scale"] = max(s_, MIN_SCALE_LOG10_SD)
        out[f"{r.ligament}:pre_elongation"] = max(p_, MIN_PRE_ELONGATION_SD_MM)
    return out


def prior_sources(names, prior: str) -> dict:
    """{fit parameter: where its prior centre and spread come from} (a column of the posterior table, role calibration.posterior)."""
    centre = {"remus2021": "Remus et al. (2021) law of the same fibres",
              "table3": "paper 1 Table 3 on elongation (Rupp et al. 2015 where Table 3 has none)"}[prior]
    out = {}
    for n in names:
        if n.endswith(":scale"):
            out[n] = f"centre: {centre}; spread: |log10 ratio| of the Remus (2021) and Table 3 laws at 2-6 mm"
        elif n.endswith(":pre_elongation"):
            out[n] = f"centre: {centre}; spread: |difference| of the two sources' pre-elongations"
        elif n == "facet_stiffness":
            out[n] = "centre: paper 1 Sect. 2.2.3 (12,000 N/m); spread: 1 decade (its own contact discretisation)"
        elif n == "disc_shear":
            out[n] = "sourced motion-segment range 53-140 N/mm (data/characteristics/disc.csv) as +-2 spreads"
    return out


#: spreads of a parameter without a sourced one (fit units): a decade of force scale, 1 mm of pre-elongation
DEFAULT_SCALE_LOG10_SD = 1.0
DEFAULT_PRE_ELONGATION_SD_MM = 1.0
#: log10 spread of a disc torque-law scale: one decade. Its centre is the disc-only fit (step 1, Eq. 3 on the disc-only
#: rows), and the same disc-only rows enter the admissible fit's likelihood as data (together one observation per
#: direction): a prior of their spread (25 %) would count that one published curve twice and make the posterior of
#: the disc laws sqrt(2) times too narrow. The prior only keeps the scale finite where no row reaches it.
DISC_TORQUE_LOG10_SD = 1.0
#: ... and where a direction has no disc-only row in the likelihood, the prior is the curve's only appearance: the
#: spread of a measured row (25 %, the validation's acceptance band; the paper publishes the disc-only fit, not its
#: specimens' spread)
DISC_CURVE_LOG10_SD = math.log10(1.25)


def default_spreads(names, lo, hi, disc_data_directions=None) -> np.ndarray:
    """Prior spreads (fit units) of the fit parameters ``names`` when none is given: :data:`DEFAULT_SCALE_LOG10_SD`
    per force scale, :data:`DEFAULT_PRE_ELONGATION_SD_MM` per pre-elongation, :data:`FACET_LOG10_SD` for the facet
    stiffness, and a quarter of the sourced log10 range (``hi - lo``) for the disc shear stiffness (the range as
    +-2 spreads)."""
    out = []
    for j, n in enumerate(names):
        if n.endswith(":scale"):
            out.append(DEFAULT_SCALE_LOG10_SD)
        elif n.endswith(":pre_elongation"):
            out.append(DEFAULT_PRE_ELONGATION_SD_MM)
        elif n == "facet_stiffness":
            out.append(FACET_LOG10_SD)
        elif n == "disc_shear":
            out.append(0.25 * float(hi[j] - lo[j]))
        elif n.startswith("disc_torque:"):
            # the disc-only curve counts once: as data where the direction has disc-only rows in the likelihood
            # (``disc_data_directions``; None: every direction), else as this prior
            as_data = disc_data_directions is None or n.split(":", 1)[1] in disc_data_directions
            out.append(DISC_TORQUE_LOG10_SD if as_data else DISC_CURVE_LOG10_SD)
        else:
            raise ValueError(f"no default prior spread for fit parameter {n!r}")
    return np.array(out, float)
