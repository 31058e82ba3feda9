"""The L4-L5 functional spinal unit (paper 1, Sect. 2.2) and its range of motion under pure moments.

``build_fsu`` turns a geometry level and a characteristic set into a :class:`SpineModel` with the
lower vertebra fixed and the upper one free (6 DOF). ``range_of_motion`` solves many scenarios
(reduction stage x direction x moment) in one batch: each stage is first brought to equilibrium
at 0 N*m, then the moment is applied by load continuation. ROM = rotation of the upper vertebra
about the loading axis relative to the stage's 0 N*m equilibrium.

Command line (:mod:`lumbar.cli`; ``python -m lumbar.experiments.fsu`` runs the same)::

    lumbar fsu --moment 10 --direction all --geometry visible_human
    python -m lumbar.cli fsu --moment 10 --direction all --geometry visible_human
"""
from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..mechanics import so3
from ..inputs import manifests
from ..inputs.characteristics import CHARACTERISTIC_SETS, resolve_characteristic_set
from ..inputs.config import default_geometry_path
from ..mechanics.elements.facet import fit_surface
from ..mechanics.elements.ligament import rupp_shape
from ..geometry import load_geometry
from ..mechanics.model import DiscSpec, SpineModel
from ..mechanics.solve import continue_rest_states, solve, stable_rest_states
from ..inputs.tables import MAIN_DIRECTIONS, STAGES

log = logging.getLogger(__name__)

# STAGES: reduction stages of the stepwise-reduction experiment (Heuer et al. 2007), in removal order, and
# MAIN_DIRECTIONS: the four loading directions (vocabularies of the tables, owned by lumbar.inputs.tables)
STAGE_LABELS = {"intact": "intact", "wo_ssl": "w/o SSL", "wo_isl": "w/o ISL", "wo_fl": "w/o FL",
                "wo_cl": "w/o CL", "wo_va": "w/o VA", "wo_pll": "w/o PLL", "wo_all": "w/o ALL"}
# what each stage removes in addition to the previous one; removing the vertebral arches (VA)
# takes the facet joints and the intertransverse ligaments (attached to the arch) with them
REMOVED_AT = {"wo_ssl": {"SSL"}, "wo_isl": {"ISL"}, "wo_fl": {"FL"}, "wo_cl": {"CL"},
              "wo_va": {"facets", "ITL"}, "wo_pll": {"PLL"}, "wo_all": {"ALL"}}
# loading direction -> (project axis index, sign); see docs/design.md for the sign conventions
DIRECTIONS = {
    "flexion": (1, 1.0), "extension": (1, -1.0),
    "lateral_bending": (0, 1.0), "lateral_bending_right": (0, 1.0), "lateral_bending_left": (0, -1.0),
    "axial_rotation": (2, 1.0), "axial_rotation_left": (2, 1.0), "axial_rotation_right": (2, -1.0),
}


def removed_structures(stage: str) -> set:
    if stage not in STAGES:
        raise ValueError(f"unknown reduction stage {stage!r}; expected one of {STAGES}")
    out = set()
    for s in STAGES[1: STAGES.index(stage) + 1]:
        out |= REMOVED_AT[s]
    return out


def disc_frame(normal) -> np.ndarray:
    """Rows e1 (anterior, orthogonal to the normal), e2 = e3 x e1, e3 = disc normal."""
    e3 = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.array([1.0, 0.0, 0.0]) - e3[0] * e3
    e1 /= np.linalg.norm(e1)
    return np.vstack([e1, np.cross(e3, e1), e3])


#: fibre-group kind of the optional follower-load cable of a unit (weight 0 in every stage mask; a caller sets its
#: mask weight to the compressive force in N)
FOLLOWER = "follower"


@dataclass
class FSU:
    model: SpineModel
    level: object
    charset: object
    group_kind: list           # ligament kind per fibre group
    surface_side: list         # "left"/"right" per facet surface
    follower_group: int | None = None   # fibre-group id of the follower-load cable (build_fsu(follower=True))

    def masks(self, stages):
        """Element masks (S, nf) and (S, nc) for a list of reduction stages (the follower cable, if any, at 0)."""
        m = self.model
        fk = np.array([self.group_kind[g] for g in m.f_group]) if m.nf else np.array([])
        fmask = np.ones((len(stages), m.nf))
        cmask = np.ones((len(stages), m.nc))
        for i, st in enumerate(stages):
            gone = removed_structures(st) | {FOLLOWER}
            if m.nf:
                fmask[i] = ~np.isin(fk, list(gone))
            if "facets" in gone:
                cmask[i] = 0.0
        return fmask, cmask


def add_level(model: SpineModel, level, charset, facet_stiffness_n_per_m=None, disc_shear_stiffness_n_per_m=None,
              exclude=()):
    """Add the disc, facet joints and ligaments of one geometry level to ``model``.

    Returns (group kinds, surface sides) of what was added. Ligament kinds absent from the
    characteristic set are left out (as the paper does for literature sets that lack them).
    """
    up, lo = model.body_index(level.upper), model.body_index(level.lower)
    disc = charset.disc
    ks = disc.k_shear if disc_shear_stiffness_n_per_m is None else disc_shear_stiffness_n_per_m
    if ks is None:
        raise ValueError("characteristic set has no disc shear stiffness: set fsu.disc_shear_stiffness_n_per_m")
    if not np.isfinite(ks) or ks <= 0:
        raise ValueError(f"disc shear stiffness must be a finite value > 0 N/m, got {ks}")
    model.add_disc(DiscSpec(up, lo, np.asarray(level.disc_centre, float), disc_frame(level.disc_normal),
                            disc.k_axial_quadratic, disc.k_axial_linear, ks, disc.k_tension,
                            disc.torque, name=level.name))
    kinds = []
    for lig in level.ligaments:
        law = charset.ligaments.get(lig.kind)
        if law is None or lig.kind in exclude:
            continue
        if hasattr(law, "a"):
            l_ref = np.linalg.norm(np.asarray(lig.upper, float) - np.asarray(lig.lower, float), axis=1) + \
                np.broadcast_to(np.asarray(lig.extra_length, float), (len(lig.upper),))
            pre, par = softplus_fibre_params(law, l_ref, f"{level.name} {lig.name}")
            model.add_fibre_group(lig.name, lig.kind, level.name, up, lo, lig.upper, lig.lower,
                                  lig.extra_length, "softplus", par, prestrain=pre)
        else:
            shape = rupp_shape(law.l_a_m, law.l_b_m, law.f_a_n, law.f_b_n, law.n_strands)
            model.add_fibre_group(lig.name, lig.kind, level.name, up, lo, lig.upper, lig.lower,
                                  lig.extra_length, "rupp", shape, prestrain=law.prestrain,
                                  scale=law.n_strands / lig.n_fibres)
        kinds.append(lig.kind)
    sides = []
    facet_stiffness_n_per_m = charset.facet.stiffness if facet_stiffness_n_per_m is None else facet_stiffness_n_per_m
    if not np.isfinite(facet_stiffness_n_per_m) or facet_stiffness_n_per_m < 0:
        raise ValueError(f"facet stiffness must be a finite value >= 0 N/m, got {facet_stiffness_n_per_m}")
    for side, fl, surf in facet_surfaces(level):
        model.add_facet(up, lo, surf, getattr(fl, "contact_set", fl.inferior), facet_stiffness_n_per_m)
        sides.append(side)
    return kinds, sides


#: a law on elongation may leave each fibre at least this fraction of its reference length as slack length
MIN_SLACK_FRACTION = 0.2


class LawDomainError(ValueError):
    """A ligament law applied outside its domain on a geometry (a pre-elongation that leaves a fibre almost no slack
    length): the model of that geometry cannot be built with that law."""


def softplus_fibre_params(law, l_ref, where=""):
    """Per-fibre (prestrain (n,), Eq. 7 parameters (n, 4)) of a softplus law for fibres of reference lengths
    ``l_ref`` (n,) [m], in the model's own-strain form (eps = 100 (l / l0 - 1), l0 = l_ref / (1 + prestrain)).

    A law on elongation (``law.law_length_m`` = L) takes eps_L = 100 (l - l0) / L with l0 = l_ref - e0, e0 =
    prestrain * L: then eps_L = eps * l0 / L, i.e. the same Eq. 7 with b and d multiplied by L / l0 per fibre (a, c
    unchanged). The paper's own rule (``law_length_m`` None) gives the set's (a, b, c, d) and prestrain to every fibre.
    """
    l_ref = np.asarray(l_ref, float)
    n = l_ref.shape[0]
    if law.law_length_m is None:
        return np.full(n, law.prestrain), np.tile([law.a, law.b, law.c, law.d], (n, 1))
    L = float(law.law_length_m)
    l0 = l_ref - law.prestrain * L
    if np.any(l0 < MIN_SLACK_FRACTION * l_ref):
        raise LawDomainError(f"ligament law on elongation {where}: pre-elongation {law.prestrain * L * 1e3:.3g} mm leaves "
                         f"a slack length below {MIN_SLACK_FRACTION:g} x the shortest fibre "
                         f"({l_ref.min() * 1e3:.3g} mm); expected prestrain_pct * law_length < "
                         f"{(1 - MIN_SLACK_FRACTION) * l_ref.min() * 1e3:.3g} mm")
    k = L / l0
    par = np.column_stack([np.full(n, law.a), law.b * k, np.full(n, law.c), law.d * k])
    return l_ref / l0 - 1.0, par


def set_ligament_law(model: SpineModel, groups, law, sel=None):
    """Rewrite, in place, the slack lengths and Eq. 7 parameters of the fibres of ``groups`` (fibre-group ids of a
    finalized model) for the softplus ``law`` (the same conversion as :func:`add_level`); ``sel``: those fibres'
    indices when the caller has them (``np.flatnonzero(np.isin(model.f_group, groups))``, kept by a fit that sets
    the law thousands of times)."""
    sel = np.flatnonzero(np.isin(model.f_group, list(groups))) if sel is None else sel
    if sel.size == 0:
        return
    pre, par = softplus_fibre_params(law, model.f_lref[sel], f"groups {list(groups)}")
    model.f_l0[sel] = model.f_lref[sel] / (1.0 + pre)
    model.f_par[sel, :4] = par


def facet_surfaces(level) -> list:
    """[(side, FacetLandmarks, FacetSurface)] of a level's facet joints (left, right; a missing side is left
    out): the cubic contact surface of paper 1 Eq. 4 fitted to the landmarks, its normal towards the joint's
    medial side, with the landmarks' contact rule ("mean_surface" where none is given)."""
    out = []
    for side in ("left", "right"):
        fl = level.facets.get(side)
        if fl is None:
            continue
        medial = np.array([0.0, -1.0 if side == "left" else 1.0, 0.0])
        out.append((side, fl, fit_surface(fl.superior, fl.inferior, medial_hint=medial,
                                          contact=getattr(fl, "contact", "mean_surface"),
                                          contact_points=getattr(fl, "contact_points", None))))
    return out


#: length [m] of the follower-load cable: its far end is fixed this far below the disc centre, along the normal, so
#: its line of action stays within 1 mrad of the disc normal through the (moving) disc centre
FOLLOWER_CABLE_LENGTH_M = 1.0


def build_fsu(geometry, charset, level="L4-L5", facet_stiffness_n_per_m=None, disc_shear_stiffness_n_per_m=None,
              contact_eps=5e-5, slack_width_pct=0.5, follower=False) -> FSU:
    """The functional unit of ``level``: lower vertebra fixed, upper free.

    ``follower``: also add a constant-tension cable from the disc centre (carried by the upper vertebra) along the
    disc normal to a point fixed ``FOLLOWER_CABLE_LENGTH_M`` below: a follower (pure axial) load whose force in N is
    its fibre-mask weight (0 in :meth:`FSU.masks`)."""
    if level not in geometry.levels:
        raise ValueError(f"geometry {geometry.name!r} has no level {level!r}; has {sorted(geometry.levels)}")
    lev = geometry.levels[level]
    m = SpineModel(contact_eps=contact_eps, slack_width_pct=slack_width_pct)
    m.add_body(lev.upper, geometry.vertebrae[lev.upper].centroid)
    m.add_body(lev.lower, geometry.vertebrae[lev.lower].centroid, fixed=True)
    kinds, sides = add_level(m, lev, charset, facet_stiffness_n_per_m, disc_shear_stiffness_n_per_m)
    gid = None
    if follower:
        c = np.asarray(lev.disc_centre, float)
        n = disc_frame(lev.disc_normal)[2]
        gid = m.add_fibre_group("follower_load", FOLLOWER, lev.name, 0, -1, c[None],
                                (c - FOLLOWER_CABLE_LENGTH_M * n)[None], 0.0, "cable", (1.0,))
        kinds = kinds + [FOLLOWER]
    m.finalize()
    return FSU(m, lev, charset, kinds, sides, gid)


#: the configuration's stiffness overrides of a unit (section ``fsu``; None = the characteristic set's own value),
#: by the names every builder takes them under (build_fsu, add_level, build_l2s1, run_set, ...): read only by
#: :func:`unit_options`
UNIT_KEYS = ("facet_stiffness_n_per_m", "disc_shear_stiffness_n_per_m")


def unit_options(config) -> dict:
    """The stiffness overrides of a configuration as the builders' keyword arguments: ``{facet_stiffness_n_per_m,
    disc_shear_stiffness_n_per_m}`` (None where the configuration leaves the set's own value). ``config``: the whole
    configuration (its ``fsu`` section is read), the ``fsu`` section itself, or None. The one place a
    configuration's unit keys are unpacked: scripts and library modules pass this on, never the keys themselves."""
    f = config or {}
    if "fsu" in f and isinstance(f["fsu"], dict):
        f = f["fsu"] or {}
    out = {}
    for k in UNIT_KEYS:
        v = f.get(k)
        if v is not None and not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
            raise ValueError(f"fsu.{k} must be a finite number >= 0 N/m or null, got {v!r}")
        out[k] = None if v is None else float(v)
    return out


def unit_stiffness(charset, config) -> tuple[float, float]:
    """(facet stiffness, disc shear stiffness) [N/m] a unit of ``charset`` built from ``config`` gets: the
    configuration's overrides where given, else the set's own values."""
    o = unit_options(config)
    k_f, k_s = o["facet_stiffness_n_per_m"], o["disc_shear_stiffness_n_per_m"]
    return (charset.facet.stiffness if k_f is None else k_f), (charset.disc.k_shear if k_s is None else k_s)


def disc_shear_override(config) -> float | None:
    """The configuration's disc shear stiffness override [N/m] (None = the set's own): for the functions that build
    their unit themselves and take only this override (the calibrations, the virtual specimens)."""
    return unit_options(config)["disc_shear_stiffness_n_per_m"]


def configured_unit(geometry, charset, config, level=None, **kw) -> FSU:
    """The unit a configuration describes, the one way from a configuration to a model: :func:`build_fsu` of
    ``level`` (default the configuration's ``fsu.level``) with ``charset`` and the configuration's stiffness
    overrides (:func:`unit_options`); ``kw`` (``follower``, ``contact_eps``, ...) goes to :func:`build_fsu`."""
    f = config or {}
    if "fsu" in f and isinstance(f["fsu"], dict):
        f = f["fsu"] or {}
    return build_fsu(geometry, charset, level or f.get("level", "L4-L5"), **unit_options(f), **kw)


def moment_loads(directions, moments_nm, nb=1, body=0):
    """External load array (B, nb, 6) of pure moments [N*m] about the project axes."""
    L = np.zeros((len(directions), nb, 6))
    for i, (d, M) in enumerate(zip(directions, moments_nm)):
        axis, sign = DIRECTIONS[d]
        L[i, body, 3 + axis] = sign * M
    return L


#: Largest rotation [deg] of the upper vertebra within the range the disc and ligament laws were fitted on (the
#: stepwise-reduction experiment to 10 N*m reached ~13 deg disc-only in flexion; beyond 20 deg the laws extrapolate).
MAX_VALID_ROTATION_DEG = 20.0


def range_of_motion(fsu: FSU, moments_nm=(1, 2.5, 5, 7.5, 10), directions=MAIN_DIRECTIONS,
                    stages=("intact",), load_steps=1, max_iter=50, tol=1e-7) -> pd.DataFrame:
    """ROM table (one row per stage x direction x moment), solved as one batch.

    ``valid`` is False where a converged state lies outside the validity of the force laws: the disc centre
    approaches the lower vertebra by more than the disc height (``disc_compression_mm``), or the upper vertebra
    rotates by more than :data:`MAX_VALID_ROTATION_DEG` from the stage's 0 N*m state (and where not converged).
    ``rest_state_stable`` is False where that 0 N*m state is a saddle (:func:`lumbar.mechanics.solve.
    stable_rest_states`: the disc-only stage, whose flexion law has negative stiffness about zero), so the ROM
    includes the snap off it.
    """
    for d in directions:
        if d not in DIRECTIONS:
            raise ValueError(f"unknown direction {d!r}; expected one of {sorted(DIRECTIONS)}")
    m = fsu.model
    stages = list(stages)
    fm_s, cm_s = fsu.masks(stages)
    zero = np.zeros((len(stages), m.nb, 6))
    r0 = solve(m, zero, fmask=fm_s, cmask=cm_s, load_steps=1, max_iter=max_iter,
               tol_force=tol, tol_moment=tol)
    if not r0.converged.all():      # a rest state not reached from the reference: continued from the stage before
        r0 = continue_rest_states(m, r0, fm_s, cm_s, max_iter=max_iter, tol_force=tol, tol_moment=tol)
    grid = [(s, d, M) for s in range(len(stages)) for d in directions for M in moments_nm]
    si = np.array([g[0] for g in grid], int)
    loads = moment_loads([g[1] for g in grid], [g[2] for g in grid], m.nb)
    res = solve(m, loads, x0=r0.x[si], R0=r0.R[si], fmask=fm_s[si], cmask=cm_s[si],
                load_steps=load_steps, max_iter=max_iter, tol_force=tol, tol_moment=tol)
    rot = so3.log(res.R[:, 0] @ np.swapaxes(r0.R[si, 0], -1, -2))
    trans = (res.x[:, 0] - r0.x[si, 0])
    axis = np.array([DIRECTIONS[g[1]][0] for g in grid])
    sign = np.array([DIRECTIONS[g[1]][1] for g in grid])
    rom = np.degrees(rot[np.arange(len(grid)), axis] * sign)
    conv = res.converged & r0.converged[si]
    # validity of the force laws: no point of the disc's upper endplate (a circle of the disc's area, carried by
    # the upper vertebra) may approach the lower endplate by more than the disc height, and the rotation from the
    # stage's 0 N*m state stays within the range the laws were fitted on (MAX_VALID_ROTATION_DEG)
    c = np.asarray(fsu.level.disc_centre, float)
    e = disc_frame(fsu.level.disc_normal)
    t = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    rim = c + np.sqrt(fsu.level.disc_csa / np.pi) * (np.cos(t)[:, None] * e[0] + np.sin(t)[:, None] * e[1])
    x_ref = m.reference_state(1)[0][0, 0]
    moved = res.x[:, 0, None] + np.einsum("bij,pj->bpi", res.R[:, 0], rim - x_ref)
    compression = (-(moved - rim) @ e[2]).max(axis=1)
    angle = np.degrees(np.linalg.norm(rot, axis=-1))
    height = float(fsu.level.disc_height)
    valid = conv & (compression < height) & (angle <= MAX_VALID_ROTATION_DEG)
    df = pd.DataFrame({
        "stage": [stages[g[0]] for g in grid],
        "direction": [g[1] for g in grid],
        "moment_nm": [float(g[2]) for g in grid],
        "rom_deg": np.where(conv, rom, np.nan),
        "rot_x_deg": np.degrees(rot[:, 0]), "rot_y_deg": np.degrees(rot[:, 1]),
        "rot_z_deg": np.degrees(rot[:, 2]),
        "trans_x_mm": trans[:, 0] * 1e3, "trans_y_mm": trans[:, 1] * 1e3, "trans_z_mm": trans[:, 2] * 1e3,
        "converged": conv,
        "residual_force_n": res.residual_force, "residual_moment_nm": res.residual_moment,
        "iterations": res.iterations,
        "disc_compression_mm": compression * 1e3,
        "valid": valid,
        "rest_state_stable": stable_rest_states(m, r0.x, r0.R, fm_s, cm_s)[si],
    })
    if not conv.all():
        log.warning("ROM: %d of %d scenarios did not converge; their rom_deg is NaN and converged=False",
                    int((~conv).sum()), len(conv))
    bad = conv & ~valid
    if bad.any():
        log.warning("ROM: %d of %d converged scenarios lie outside the validity of the force laws (disc compressed "
                    "beyond its height %.1f mm, or a rotation above %g deg; largest %.1f mm, %.1f deg at %g N*m): "
                    "valid=False", int(bad.sum()), len(conv), height * 1e3, MAX_VALID_ROTATION_DEG,
                    compression[bad].max() * 1e3, angle[bad].max(), max(g[2] for g, b in zip(grid, bad) if b))
    return df


def main(argv=None, prog: str = "python -m lumbar.experiments.fsu") -> int:
    p = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    p.add_argument("--moment", type=float, nargs="+", default=[10.0], help="pure moment(s) [N*m]")
    p.add_argument("--direction", default="all",
                   help="all | comma list of " + ", ".join(sorted(DIRECTIONS)))
    p.add_argument("--geometry", default="visible_human",
                   help="visible_human (default: the embedded Visible Human set, as the workflow) | myo_sim | "
                        "synthetic")
    p.add_argument("--geometry-dir", default=None,
                   help="folder of the Visible Human set (--geometry visible_human; default: the configuration's "
                        "geometry.path)")
    p.add_argument("--set", default="calibrated", choices=CHARACTERISTIC_SETS, help="characteristic set")
    p.add_argument("--calibrated-dir", default=manifests.calibrated_dir(),
                   help="where --set calibrated comes from: the workflow's calibration output (used when it holds "
                        "disc.csv; else the paper's published set in data/characteristics)")
    p.add_argument("--stage", default="intact", help="all | comma list of " + ", ".join(STAGES))
    p.add_argument("--level", default="L4-L5",
                   help="motion segment to load, 'upper-lower': L1-L2, L2-L3, L3-L4, L4-L5 or L5-S1 (default L4-L5, "
                        "the unit of paper 1)")
    p.add_argument("--shear-stiffness", type=float, default=None, help="disc shear stiffness [N/m]")
    p.add_argument("--facet-stiffness", type=float, default=None, help="facet contact stiffness [N/m]")
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    directions = MAIN_DIRECTIONS if a.direction == "all" else tuple(a.direction.split(","))
    stages = STAGES if a.stage == "all" else tuple(a.stage.split(","))
    for m in a.moment:
        if not np.isfinite(m) or m < 0:
            p.error(f"--moment must be finite and >= 0 N*m, got {m}")
    geometry_dir = a.geometry_dir
    if a.geometry == "visible_human" and geometry_dir is None:
        geometry_dir = default_geometry_path()
        if not geometry_dir.is_dir():
            p.error(f"--geometry visible_human: no --geometry-dir given and the configuration's geometry.path "
                    f"{str(geometry_dir)!r} is not a folder; pass --geometry-dir <visible_human_lss folder>")
    try:
        geo = load_geometry(a.geometry, path=geometry_dir)
        cs = resolve_characteristic_set(a.set, calibrated_dir=a.calibrated_dir)
        fsu = build_fsu(geo, cs, a.level, facet_stiffness_n_per_m=a.facet_stiffness,
                        disc_shear_stiffness_n_per_m=a.shear_stiffness)
        df = range_of_motion(fsu, a.moment, directions, stages)
    except (ValueError, KeyError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    cols = ["stage", "direction", "moment_nm", "rom_deg", "rot_x_deg", "rot_y_deg", "rot_z_deg",
            "trans_x_mm", "trans_y_mm", "trans_z_mm", "disc_compression_mm", "converged", "valid",
            "rest_state_stable"]
    origin = (a.calibrated_dir if a.set == "calibrated" and (Path(a.calibrated_dir) / "disc.csv").is_file()
              else "data/characteristics (as published)")
    print(f"# geometry={geo.name} set={cs.name} ({origin}) level={a.level}")
    print(df[cols].to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    ok = bool(df["converged"].all())
    if not ok:
        print(f"# {int((~df['converged']).sum())} scenario(s) did NOT converge", file=sys.stderr)
    invalid = df["converged"] & ~df["valid"]
    if invalid.any():
        print(f"# {int(invalid.sum())} scenario(s) (moment {', '.join(f'{m:g}' for m in sorted(set(df.loc[invalid, 'moment_nm'])))} "
              f"N*m) lie OUTSIDE the validity of the force laws (valid=False: disc compressed beyond its height "
              f"{geo.levels[a.level].disc_height * 1e3:.1f} mm or rotation > {MAX_VALID_ROTATION_DEG:g} deg); "
              "their numbers are extrapolations, not predictions", file=sys.stderr)
    saddle = sorted(set(df.loc[~df["rest_state_stable"], "stage"]))
    if saddle:
        print(f"# stage(s) {', '.join(saddle)}: the 0 N*m state the ROM is measured from is unstable "
              "(rest_state_stable=False; docs/validity.md, Known departures)", file=sys.stderr)
    return 0 if ok and not invalid.any() else 1


if __name__ == "__main__":
    sys.exit(main())
