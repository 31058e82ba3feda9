"""Virtual specimens: seeded perturbations of a (geometry, characteristic set) pair.

Where published experimental tables are not available, the workflow generates *surrogate* tables by
running the experiment on virtual specimens, each of which differs from the calibration model the way a
cadaver differs from a model: its geometry is scaled and its insertion points displaced, its passive
characteristics are perturbed log-normally, and the measurement carries noise. Every table produced from
virtual specimens has ``kind = surrogate`` and the word "surrogate" in its file name.

The experiment-specific generators (stepwise reduction ROM, in-vitro IDP) build on ``virtual_specimen``.
"""
from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SpecimenVariation:
    """Spread of the virtual specimens around the calibration model (all defaults are modelling choices)."""

    geometry_scale_sd: float = 0.03      # sd of log isotropic scale of the whole geometry (about 3 %)
    insertion_sd_m: float = 0.0007       # sd of each ligament-fibre end displacement per axis [m]
    landmark_sd_m: float = 0.0002        # sd of each facet landmark displacement per axis [m]
    force_sd: float = 0.20               # sd of log force scale of each ligament law
    prestrain_sd_pct: float = 1.0        # sd of each ligament's prestrain [% strain]
    disc_sd: float = 0.10                # sd of log scale of the disc torque law, per direction
    facet_sd: float = 0.20               # sd of log facet stiffness

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not np.isfinite(v) or v < 0:
                raise ValueError(f"SpecimenVariation.{f.name} must be finite and >= 0, got {v}")


def _scale_law(law, factor, dprestrain):
    if hasattr(law, "a"):      # softplus: force scales with a and c
        return dataclasses.replace(law, a=law.a * factor, c=law.c * factor,
                                   prestrain_pct=law.prestrain_pct + dprestrain)
    return dataclasses.replace(law, f_a_n=law.f_a_n * factor, f_b_n=law.f_b_n * factor,
                               prestrain_pct=law.prestrain_pct + dprestrain)


def perturb_characteristics(charset, rng: np.random.Generator, v: SpecimenVariation):
    """A copy of ``charset`` with log-normal force scales, shifted prestrains, scaled disc and facets."""
    ligs = {}
    for kind in sorted(charset.ligaments):
        ligs[kind] = _scale_law(charset.ligaments[kind], float(np.exp(rng.normal(0, v.force_sd))),
                                float(rng.normal(0, v.prestrain_sd_pct)))
    torque = {}
    for d in sorted(charset.disc.torque):
        p1, p2, p3 = charset.disc.torque[d]
        f = float(np.exp(rng.normal(0, v.disc_sd)))
        torque[d] = (p1 * f, p2, p3 * f)
    disc = dataclasses.replace(charset.disc, torque=torque) if dataclasses.is_dataclass(charset.disc) \
        else _ns_replace(charset.disc, torque=torque)
    k = charset.facet.stiffness * float(np.exp(rng.normal(0, v.facet_sd)))
    facet = dataclasses.replace(charset.facet, stiffness=k) if dataclasses.is_dataclass(charset.facet) \
        else _ns_replace(charset.facet, stiffness=k)
    if dataclasses.is_dataclass(charset):
        return dataclasses.replace(charset, ligaments=ligs, disc=disc, facet=facet)
    return _ns_replace(charset, ligaments=ligs, disc=disc, facet=facet)


def _ns_replace(ns, **kw):
    out = copy.copy(ns)
    for k, val in kw.items():
        setattr(out, k, val)
    return out


def perturb_geometry(geometry, rng: np.random.Generator, v: SpecimenVariation, levels=None):
    """A deep copy of ``geometry`` scaled about the first level's disc centre, with displaced insertions.

    Only the levels in ``levels`` (default: all) are perturbed; meshes are scaled with the points.
    """
    geo = copy.deepcopy(geometry)
    names = sorted(geo.levels) if levels is None else list(levels)
    origin = np.asarray(geo.levels[names[0]].disc_centre, float).copy()
    s = float(np.exp(rng.normal(0, v.geometry_scale_sd)))

    def sc(p):
        return origin + s * (np.asarray(p, float) - origin)

    for vert in geo.vertebrae.values():
        vert.centroid = sc(vert.centroid)
        if getattr(vert, "mesh", None) is not None:
            vert.mesh.apply_translation(-origin)
            vert.mesh.apply_scale(s)
            vert.mesh.apply_translation(origin)
    for name in sorted(geo.levels):
        lev = geo.levels[name]
        lev.disc_centre = sc(lev.disc_centre)
        lev.disc_csa = lev.disc_csa * s**2
        lev.disc_height = lev.disc_height * s
        jitter = name in names
        for side in sorted(lev.facets):
            f = lev.facets[side]
            f.superior, f.inferior = sc(f.superior), sc(f.inferior)
            if jitter:
                f.superior = f.superior + rng.normal(0, v.landmark_sd_m, f.superior.shape)
                f.inferior = f.inferior + rng.normal(0, v.landmark_sd_m, f.inferior.shape)
        for lig in lev.ligaments:
            lig.upper, lig.lower = sc(lig.upper), sc(lig.lower)
            lig.extra_length = np.asarray(lig.extra_length, float) * s
            if jitter:
                lig.upper = lig.upper + rng.normal(0, v.insertion_sd_m, lig.upper.shape)
                lig.lower = lig.lower + rng.normal(0, v.insertion_sd_m, lig.lower.shape)
    geo.name = f"{geometry.name}_virtual_specimen"
    return geo


def virtual_specimen(geometry, charset, rng: np.random.Generator, variation: SpecimenVariation | None = None,
                     levels=None):
    """One virtual specimen: (perturbed geometry, perturbed characteristic set)."""
    v = variation or SpecimenVariation()
    return perturb_geometry(geometry, rng, v, levels), perturb_characteristics(charset, rng, v)


def specimen_rngs(seed: int, n: int):
    """Independent, reproducible generators for n specimens (numpy SeedSequence spawning)."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n)]
