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
import logging
import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from . import effects as fx
from .fsu import MAIN_DIRECTIONS, STAGES, LawDomainError, build_fsu
from ..mechanics.idp import DISC_AREA_M2, idp_per_newton
from .l2s1 import LEVELS, derive_cables, run_set
from .stepwise_reduction import simulate_stepwise_reduction

log = logging.getLogger(__name__)


def _check_design(n_specimens, noise_sd, name, unit) -> int:
    """The virtual-specimen design of a surrogate table: ``n_specimens`` >= 1 (returned as int) and a finite
    measurement-noise SD >= 0 (``name`` [``unit``] in the message)."""
    n = int(n_specimens)
    if n < 1:
        raise ValueError(f"n_specimens must be >= 1, got {n}")
    if not np.isfinite(noise_sd) or noise_sd < 0:
        raise ValueError(f"{name} must be finite and >= 0 {unit}, got {noise_sd}")
    return n


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


#: a jittered fibre keeps at least this fraction of its length (the capsular fibres are 1-4 mm long, about the
#: insertion jitter): a draw that shortens it more is drawn again from the same stream
MIN_JITTER_LENGTH_FRACTION = 0.7


def _jitter_fibres(upper, lower, extra, rng, sd, max_draws=50):
    """Fibre ends displaced by N(0, sd) per axis; fibres shortened below MIN_JITTER_LENGTH_FRACTION re-drawn."""
    upper, lower = np.asarray(upper, float), np.asarray(lower, float)
    L0 = np.linalg.norm(upper - lower, axis=1) + extra
    du = rng.normal(0, sd, upper.shape)
    dl = rng.normal(0, sd, lower.shape)
    for _ in range(max_draws):
        bad = np.linalg.norm(upper + du - lower - dl, axis=1) + extra < MIN_JITTER_LENGTH_FRACTION * L0
        if not bad.any():
            break
        du[bad] = rng.normal(0, sd, (int(bad.sum()), 3))
        dl[bad] = rng.normal(0, sd, (int(bad.sum()), 3))
    return upper + du, lower + dl


def perturb_geometry(geometry, rng: np.random.Generator, v: SpecimenVariation, levels=None):
    """A deep copy of ``geometry`` scaled about the first level's disc centre, with displaced insertions.

    Only the levels in ``levels`` (default: all) are perturbed; meshes are scaled with the points, and the copy
    records the scaling as ``similarity`` (nominal geometry, 4x4 matrix), composed with that of ``geometry``.
    """
    base, T0 = geometry.similarity or (geometry, np.eye(4))
    # the nominal geometry a specimen refers to is shared, not copied
    geo = copy.deepcopy(geometry, {} if base is geometry else {id(base): base})
    names = sorted(geo.levels) if levels is None else list(levels)
    origin = np.asarray(geo.levels[names[0]].disc_centre, float).copy()
    s = float(np.exp(rng.normal(0, v.geometry_scale_sd)))
    S = np.eye(4)
    S[:3, :3] *= s
    S[:3, 3] = (1.0 - s) * origin
    geo.similarity = (base, S @ T0)

    def sc(p):
        return origin + s * (np.asarray(p, float) - origin)

    for vert in geo.vertebrae.values():
        vert.centroid = sc(vert.centroid)
        if getattr(vert, "mesh", None) is not None:      # the vertices set at once (three transforms re-hashed it)
            vert.mesh.vertices = origin + s * (np.asarray(vert.mesh.vertices) - origin)
    for name in sorted(geo.levels):
        lev = geo.levels[name]
        lev.disc_centre = sc(lev.disc_centre)
        lev.disc_csa = lev.disc_csa * s**2
        lev.disc_height = lev.disc_height * s
        jitter = name in names
        for side in sorted(lev.facets):
            f = lev.facets[side]
            f.superior, f.inferior = sc(f.superior), sc(f.inferior)
            if f.contact_points is not None:
                f.contact_points = sc(f.contact_points)
            if jitter:
                f.superior = f.superior + rng.normal(0, v.landmark_sd_m, f.superior.shape)
                f.inferior = f.inferior + rng.normal(0, v.landmark_sd_m, f.inferior.shape)
                if f.contact_points is not None:
                    f.contact_points = f.contact_points + rng.normal(0, v.landmark_sd_m, f.contact_points.shape)
        for lig in lev.ligaments:
            lig.upper, lig.lower = sc(lig.upper), sc(lig.lower)
            lig.extra_length = np.asarray(lig.extra_length, float) * s
            if jitter:
                lig.upper, lig.lower = _jitter_fibres(lig.upper, lig.lower, lig.extra_length, rng, v.insertion_sd_m)
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


# ---------------------------------------------------------------- stepwise-reduction surrogate
def _variation(variation) -> SpecimenVariation:
    if variation is None:
        return SpecimenVariation()
    if isinstance(variation, SpecimenVariation):
        return variation
    known = {f.name for f in dataclasses.fields(SpecimenVariation)}
    bad = sorted(set(variation) - known)
    if bad:
        raise ValueError(f"unknown variation key(s) {bad}; expected some of {sorted(known)}")
    return SpecimenVariation(**dict(variation))


def stepwise_reduction_table(geometry, charset, seed, n_specimens=8, variation=None, noise_sd_deg=0.3,
                             effects=None, moments_nm=(1.0, 2.5, 5.0, 7.5, 10.0), level="L4-L5",
                             k_shear=None, max_iter=50, tol=1e-7):
    """Surrogate stepwise-reduction ROM table (Heuer et al. 2007 layout) from ``n_specimens`` virtual specimens.

    Each specimen = ``virtual_specimen(geometry, charset, rng)`` with ``rng`` from
    ``specimen_rngs(seed, n_specimens)``; its 160 scenarios (8 stages x moments x 4 directions) are
    simulated (``lumbar.experiments.stepwise_reduction.simulate_stepwise_reduction``, with the extra physical
    ``effects``), and Gaussian measurement noise of ``noise_sd_deg`` is added per specimen and scenario
    (the same rng, after the perturbation). Per scenario: mean, min and max over the specimens that reached
    equilibrium; a specimen without equilibrium in a scenario is dropped from that row with a log line
    and the row's ``n_specimens`` is reduced; a row no specimen reached is left out (logged).
    Deterministic for a seed. Columns: stage, direction, moment_nm, rom_mean_deg, rom_min_deg,
    rom_max_deg, n_specimens, kind (= "surrogate"), source.
    """
    n_specimens = _check_design(n_specimens, noise_sd_deg, "noise_sd_deg", "deg")
    v = _variation(variation)
    def one(rng):
        geo_k, cs_k = virtual_specimen(geometry, charset, rng, v, levels=[level])
        try:
            fsu = build_fsu(geo_k, cs_k, level, disc_shear_stiffness_n_per_m=k_shear)
        except LawDomainError as exc:    # its drawn prestrain on its jittered short fibres: no model, re-drawn
            log.info("virtual specimen without a model (%s)", exc)
            return None, None, None
        sim = simulate_stepwise_reduction(fsu, STAGES, MAIN_DIRECTIONS, moments_nm, effects=effects,
                                          max_iter=max_iter, tol=tol)
        rom = sim["rom_deg"].to_numpy(float) + rng.normal(0.0, noise_sd_deg, len(sim))
        return sim, rom, sim["converged"].to_numpy(bool)

    sim, roms, redrawn, limit = _without_survivor_bias(one, int(seed), n_specimens, log)
    for k in range(len(roms)):
        neg = np.isfinite(roms[k]) & (roms[k] < 0)
        if neg.any():
            log.info("virtual specimen %d: %d noisy ROM value(s) below 0 deg set to 0", k, int(neg.sum()))
            roms[k] = np.where(neg, 0.0, roms[k])
    for i in np.flatnonzero(limit):
        r = sim.iloc[i]
        log.info("no equilibrium for most virtual specimens at %s %s %g N*m (a limit of the model, not of one "
                 "specimen): row left out", r["stage"], r["direction"], r["moment_nm"])
    A = np.vstack(roms)
    A[:, limit] = np.nan
    n = np.isfinite(A).sum(axis=0)
    keys = sim[["stage", "direction", "moment_nm"]].reset_index(drop=True)
    with np.errstate(all="ignore"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean, lo, hi = np.nanmean(A, 0), np.nanmin(A, 0), np.nanmax(A, 0)
    # provenance text written into the result tables: names the function that made them
    src = (f"lumbar.experiments.virtual_experiment.stepwise_reduction_table(seed={int(seed)}, n_specimens={n_specimens}, "
           f"noise_sd_deg={noise_sd_deg:g}, variation={dataclasses.asdict(v)}"
           + (f", effects={dict(effects)}" if effects else "")
           + f"); calibration model: geometry '{geometry.name}' {level} + characteristic set '{charset.name}'"
           + (f"; {redrawn} specimen(s) without equilibrium re-drawn (seeded)" if redrawn else ""))
    out = pd.DataFrame({"stage": keys["stage"], "direction": keys["direction"], "moment_nm": keys["moment_nm"],
                        "rom_mean_deg": mean, "rom_min_deg": lo, "rom_max_deg": hi, "n_specimens": n,
                        "kind": "surrogate", "source": src})
    empty = n == 0
    for i in np.flatnonzero(empty):
        r = keys.iloc[i]
        log.info("no virtual specimen reached equilibrium at %s %s %g N*m: row left out",
                 r["stage"], r["direction"], r["moment_nm"])
    reduced = int(((n < n_specimens) & ~empty).sum())
    if reduced:
        log.warning("%d row(s) have fewer than %d specimens (specimens without equilibrium after every re-draw; "
                    "reported in n_specimens)", reduced, n_specimens)
    return out[~empty].reset_index(drop=True)


def _without_survivor_bias(simulate_one, seed, n_specimens, log, max_redraws=None):
    """Specimens for a surrogate table without survivor bias.

    ``simulate_one(rng) -> (sim, values, converged)``, or (None, None, None) for a specimen without a model (a drawn
    ligament law outside its domain on the specimen's fibres). A scenario where most of the first ``n_specimens``
    with a model lack an equilibrium is a limit of the model (e.g. the disc-only flexion law's peak), not of one
    specimen: it is returned in ``limit`` and left out of the table. A specimen without a model, or without
    equilibrium in any other scenario, is replaced as a whole by the next specimen of a seeded reserve stream
    (``SeedSequence(seed).spawn``, after the ``n_specimens`` of the table, so the first specimens are unchanged), so
    every row averages the same specimens instead of the survivors of that row. Only when the reserve
    (``max_redraws``, default 2 n) runs out is a specimen kept with its missing rows (then reported by a reduced
    ``n_specimens``). Returns (sim, values list, number re-drawn, limit mask)."""
    max_redraws = 2 * n_specimens if max_redraws is None else int(max_redraws)
    rngs = specimen_rngs(seed, n_specimens + max_redraws)
    first = [simulate_one(r) for r in rngs[:n_specimens]]
    modelled = [f for f in first if f[0] is not None]
    if not modelled:
        raise LawDomainError(f"none of the first {n_specimens} virtual specimens has a model (every draw puts a "
                             "ligament law outside its domain on the specimen's fibres; the log names them)")
    sim = modelled[0][0]
    conv = np.vstack([c for _, _, c in modelled])
    limit = conv.mean(0) < 0.5
    none = (np.full(len(sim), np.nan), np.zeros(len(sim), bool))
    vals, redrawn, nxt = [], 0, n_specimens
    for k, (s_k, val, c) in enumerate(first):
        if s_k is None:
            val, c = none
        while not (c | limit).all() and nxt < len(rngs):
            bad = np.flatnonzero(~(c | limit))
            why = ("no model" if s_k is None else
                   f"no equilibrium in {len(bad)} scenario(s) (first: "
                   f"{' '.join(map(str, sim.iloc[bad[0]].to_dict().values()))})")
            log.info("virtual specimen %d: %s; re-drawn as reserve specimen %d", k, why, nxt)
            s_k, val, c = simulate_one(rngs[nxt])
            if s_k is None:
                val, c = none
            nxt += 1
            redrawn += 1
        if not (c | limit).all():
            log.warning("virtual specimen %d: still no equilibrium in %d scenario(s) after the reserve ran out; "
                        "reported as a reduced n_specimens in those rows", k, int((~(c | limit)).sum()))
        vals.append(np.where(c, val, np.nan))
    return sim, vals, redrawn, limit


# ---------------------------------------------------------------- in-vitro IDP surrogate
def idp_table(geometry, charset, seed, n_specimens=7, variation=None, noise_sd_mpa=0.02, effects=None,
              cables=None, idp_formula="paper1", k_shear=None, max_iter=50, tol=1e-7):
    """Surrogate L4-L5 IDP table (Wilke et al. 1996 layout: 7 muscle set-ups x 7 load cases, L2-S1).

    Each specimen = ``virtual_specimen(geometry, charset, rng)`` (all four levels L2-L3..L5-S1 perturbed)
    with ``rng`` from ``specimen_rngs(seed, n_specimens)``; its 49 scenarios are solved with
    ``lumbar.experiments.l2s1.run_set`` and Gaussian measurement noise of ``noise_sd_mpa`` [MPa] is added per specimen
    and scenario (a reading below 0, near an unloaded disc, is cut at 0 as a transducer reads it). ``effects``: optional {"muscle_setup/load_case": delta_mpa} ("*" matches any) added to
    every specimen's IDP, for effects the model lacks (default none), or {name: value} of an IDP effect of
    ``lumbar.experiments.effects`` (axial_preload, idp_moment_term, disc_load_share; hidden-effect fixtures).
    Per scenario: mean and sample SD over the specimens that reached equilibrium; a specimen without
    equilibrium is dropped from that row with a log line and ``n_specimens`` reduced; a row no specimen reached is left out (logged).
    A specimen without a model (a drawn ligament law outside its domain on its fibres) is re-drawn from a seeded
    reserve (logged). Columns: muscle_setup, load_case, idp_mean_mpa, idp_sd_mpa, n_specimens, kind (= "surrogate"), source.
    """
    n_specimens = _check_design(n_specimens, noise_sd_mpa, "noise_sd_mpa", "MPa")
    for key, delta in (effects or {}).items():
        if key in fx.EFFECTS:
            fx.check_effect(key, delta)
            if "idp_invitro" not in fx.EFFECTS[key].experiments or key not in fx.effect_names(kind="idp"):
                raise ValueError(f"effect {key!r} does not act on the IDP from the disc loads; IDP effects: "
                                 f"{fx.effect_names(kind='idp')}")
    v = _variation(variation)
    cables = derive_cables() if cables is None else cables
    vals = []
    # a specimen without a model (a drawn law outside its domain on its fibres) is replaced by the next of a seeded
    # reserve, after the n_specimens of the table (their streams do not depend on the reserve's size)
    rngs = specimen_rngs(int(seed), 3 * n_specimens)
    reserve = iter(range(n_specimens, len(rngs)))
    for k in range(n_specimens):
        rng = rngs[k]
        while True:
            geo_k, cs_k = virtual_specimen(geometry, charset, rng, v, levels=list(LEVELS))
            try:
                sim, _ = run_set(geo_k, cs_k, cables, idp_formula=idp_formula, disc_shear_stiffness_n_per_m=k_shear,
                                 max_iter=max_iter, tol=tol, specimen=True)
                break
            except LawDomainError as exc:
                j = next(reserve, None)
                if j is None:
                    raise LawDomainError(f"virtual specimen {k}: no model after the reserve of {2 * n_specimens} "
                                         f"specimens ran out ({exc})") from exc
                log.info("virtual specimen %d: no model (%s); re-drawn as reserve specimen %d", k, exc, j)
                rng = rngs[j]
        idp = sim["idp_mpa"].to_numpy(float) + rng.normal(0.0, noise_sd_mpa, len(sim))
        for key, delta in (effects or {}).items():
            if key in fx.EFFECTS:      # a discrepancy candidate acting on the IDP from the disc loads
                per_n = idp_per_newton(idp_formula, geo_k.levels["L4-L5"].disc_csa)
                idp = idp + fx.idp_delta(key, float(delta), sim["idp_mpa"].to_numpy(float) * 1e6,
                                          sim["disc_moment_sagittal_nm"].to_numpy(float),
                                          per_n) / 1e6 - sim["idp_mpa"].to_numpy(float)
                continue
            ms, lc = (str(key).split("/") + ["*"])[:2]
            hit = ((sim["muscle_setup"] == ms) | (ms == "*")) & ((sim["load_case"] == lc) | (lc == "*"))
            idp = idp + np.where(hit.to_numpy(), float(delta), 0.0)
        idp = np.maximum(idp, 0.0)      # a nucleus pressure transducer reads >= 0 (noise near an unloaded disc)
        conv = sim["converged"].to_numpy(bool)
        for i in np.flatnonzero(~conv):
            log.info("virtual specimen %d: no equilibrium at %s/%s; dropped from that row",
                     k, sim["muscle_setup"].iat[i], sim["load_case"].iat[i])
        vals.append(np.where(conv, idp, np.nan))
    A = np.vstack(vals)
    n = np.isfinite(A).sum(axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(A, 0)
        sd = np.where(n > 1, np.nanstd(A, 0, ddof=1), 0.0)
    # provenance text written into the result tables: names the function that made them
    src = (f"lumbar.experiments.virtual_experiment.idp_table(seed={int(seed)}, n_specimens={n_specimens}, "
           f"noise_sd_mpa={noise_sd_mpa:g}, variation={dataclasses.asdict(v)}"
           + (f", effects={dict(effects)}" if effects else "")
           + f", idp_formula={idp_formula}); calibration model: geometry '{geometry.name}' L2-S1 + "
             f"characteristic set '{charset.name}'")
    out = pd.DataFrame({"muscle_setup": sim["muscle_setup"], "load_case": sim["load_case"],
                        "idp_mean_mpa": mean, "idp_sd_mpa": sd, "n_specimens": n,
                        "kind": "surrogate", "source": src})
    empty = n == 0
    for i in np.flatnonzero(empty):
        log.warning("no virtual specimen reached equilibrium at %s/%s: row left out",
                    out["muscle_setup"].iat[i], out["load_case"].iat[i])
    reduced = int(((n < n_specimens) & ~empty).sum())
    if reduced:
        log.warning("%d IDP row(s) have fewer than %d specimens (non-converged specimens dropped)", reduced,
                    n_specimens)
    return out[~empty].reset_index(drop=True)


# ---------------------------------------------------------------- per-specimen responses (discrepancy discovery)
def modified_charset(charset, disc_scale=1.0, remove_ligaments=()):
    """A characteristic set changed in a way the effect registry (:mod:`lumbar.experiments.effects`) does not hold,
    for the out-of-library cases of the discrepancy benchmark: the disc's torque laws (p1, p3 of Eq. 3), axial and
    shear stiffness scaled by ``disc_scale`` (stiffer > 1, softer < 1); the ligaments ``remove_ligaments`` left out
    (``lumbar.experiments.fsu.add_level`` builds no fibres for a kind without a law)."""
    f = float(disc_scale)
    if not np.isfinite(f) or f <= 0:
        raise ValueError(f"disc_scale must be finite and > 0, got {disc_scale!r}")
    unknown = sorted(set(remove_ligaments) - set(charset.ligaments))
    if unknown:
        raise ValueError(f"cannot remove ligament(s) {unknown}: the set has {sorted(charset.ligaments)}")
    disc = charset.disc
    if f != 1.0:
        torque = {d: (p1 * f, p2, p3 * f) for d, (p1, p2, p3) in disc.torque.items()}
        kw = dict(torque=torque, k_axial_quadratic=disc.k_axial_quadratic * f, k_axial_linear=disc.k_axial_linear * f,
                  k_shear=None if disc.k_shear is None else disc.k_shear * f)
        disc = dataclasses.replace(disc, **kw) if dataclasses.is_dataclass(disc) else _ns_replace(disc, **kw)
    ligs = {k: v for k, v in charset.ligaments.items() if k not in set(remove_ligaments)}
    if dataclasses.is_dataclass(charset):
        return dataclasses.replace(charset, disc=disc, ligaments=ligs)
    return _ns_replace(charset, disc=disc, ligaments=ligs)


def rom_specimens(geometry, charset, seed, n_specimens, scenarios, variation=None, variants=(({}, None),),
                  level="L4-L5", k_shear=None, max_iter=50, tol=1e-7, retry_load_steps=()):
    """ROM [deg] of ``n_specimens`` virtual specimens (no measurement noise) in every scenario of ``scenarios``
    (stage, direction, moment_nm), for every model variant: ``variants`` = [(effects {name: value} of
    :data:`lumbar.experiments.effects.SOLVER_EFFECTS`, modification dict of :func:`modified_charset` or None)].

    Specimen k is ``virtual_specimen(geometry, charset, rng_k)`` with ``rng_k`` from ``specimen_rngs(seed, n)``, the
    same specimens for every variant and for every call with that seed (the first k specimens do not depend on
    ``n_specimens``); the variants sharing a modification are solved as one
    :class:`lumbar.experiments.effects.FsuVariants` batch per specimen. A specimen whose variant puts a ligament law
    outside its domain on the specimen's geometry (:class:`lumbar.experiments.fsu.LawDomainError`: a planted
    prestrain on a specimen with short fibres) has no model: its rows are NaN and not converged, and an INFO line
    says which. Returns (rom (K, G, n) with NaN where a specimen has no equilibrium or no model, converged
    (K, G, n))."""
    _check_design(n_specimens, 0.0, "noise", "deg")
    v = _variation(variation)
    scen = scenarios.reset_index(drop=True)
    variants = list(variants)
    groups: dict = {}
    for j, (eff, mod) in enumerate(variants):
        groups.setdefault(tuple(sorted((mod or {}).items())), []).append(j)
    K, G, n = int(n_specimens), len(variants), len(scen)
    rom, conv = np.full((K, G, n), np.nan), np.zeros((K, G, n), bool)
    for k, rng in enumerate(specimen_rngs(seed, K)):
        geo_k, cs_k = virtual_specimen(geometry, charset, rng, v, levels=[level])
        for mod, js in groups.items():
            cs_m = modified_charset(cs_k, **dict(mod)) if mod else cs_k
            try:
                fv = fx.FsuVariants(build_fsu(geo_k, cs_m, level, disc_shear_stiffness_n_per_m=k_shear))
            except LawDomainError as exc:
                log.info("virtual specimen %d, variant %s: no model (%s); its ROM is left out", k,
                         dict(mod) or "nominal", exc)
                continue
            names = sorted({name for j in js for name in variants[j][0]})
            values = {name: np.array([float(variants[j][0].get(name, 0.0)) for j in js]) for name in names}
            if not values:
                values = {}
            r, c, _, _ = fv.simulate(scen, values, max_iter=max_iter, tol=tol, retry_load_steps=retry_load_steps)
            if not values:
                r, c = np.broadcast_to(r, (len(js), n)), np.broadcast_to(c, (len(js), n))
            rom[k, js], conv[k, js] = np.where(c, r, np.nan), c
    return rom, conv


def idp_specimens(geometry, charset, seed, n_specimens, variation=None, cables=None, idp_formula="paper1",
                  disc_area_m2=DISC_AREA_M2, k_shear=None, disc_scale=1.0, max_iter=50, tol=1e-7,
                  first=0) -> pd.DataFrame:
    """Per-specimen L2-S1 results (no measurement noise) of ``n_specimens`` virtual specimens, as
    :func:`idp_table` makes them (``virtual_specimen`` with ``specimen_rngs(seed, n)``, all four levels perturbed;
    the first k specimens do not depend on ``n_specimens``; ``first``: start at specimen ``first`` of the stream, so
    a stream can be made in parts); ``disc_scale``: every specimen's discs scaled by
    :func:`modified_charset` (an out-of-library change). One row per specimen and scenario: specimen, muscle_setup,
    load_case, converged, idp_mpa (NaN without equilibrium), disc_axial_force_n, disc_moment_sagittal_nm and
    idp_per_newton_pa (the specimen's L4-L5 IDP per newton of disc force, for the IDP effects)."""
    _check_design(n_specimens, 0.0, "noise", "MPa")
    v = _variation(variation)
    cables = derive_cables() if cables is None else cables
    out = []
    for k, rng in enumerate(specimen_rngs(seed, int(first) + int(n_specimens))[int(first):], start=int(first)):
        geo_k, cs_k = virtual_specimen(geometry, charset, rng, v, levels=list(LEVELS))
        if disc_scale != 1.0:
            cs_k = modified_charset(cs_k, disc_scale=disc_scale)
        sim, _ = run_set(geo_k, cs_k, cables, idp_formula=idp_formula, disc_shear_stiffness_n_per_m=k_shear, max_iter=max_iter, tol=tol,
                         specimen=True)
        d = sim[["muscle_setup", "load_case", "converged", "idp_mpa", "disc_axial_force_n",
                 "disc_moment_sagittal_nm"]].copy()
        d.insert(0, "specimen", k)
        d["idp_per_newton_pa"] = idp_per_newton(idp_formula, geo_k.levels["L4-L5"].disc_csa, disc_area_m2)
        out.append(d)
    return pd.concat(out, ignore_index=True)
