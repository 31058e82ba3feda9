"""How a motion segment shares a load between disc, facet joints and ligaments.

For one level of a :class:`~lumbar.mechanics.model.SpineModel` (the L4-L5 unit, or any level of a longer chain),
:func:`structure_loads` returns the force and the moment that each structure of the level exerts on the level's
upper vertebra, the moment taken about the disc centre carried by that vertebra. The structures are the disc, the
left and right facet joints and every ligament kind; their sum balances the external load on the part above the
level (for a unit under a pure moment: minus the applied moment, a check every caller can assert with
:func:`balance_residual`).

:func:`moment_rotation_curves` applies pure moments in small steps (continuation: each step starts from the
previous equilibrium, so that a jump of the rotation between two steps is visible) and records, at every step, the
rotation and the internal loads; :func:`axial_compression_curve` does the same for a follower load through the disc
centre (a constant-magnitude cable along the disc normal). Everything is SI inside; the tables convert to N, N*m and
degrees with the unit in every column name. Frame and sign conventions: docs/design.md.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..mechanics import so3
from ..mechanics.model import SpineModel
from ..mechanics.solve import continue_rest_states, solve, solve_sequence
from .fsu import DIRECTIONS, FSU, disc_frame, moment_loads

log = logging.getLogger(__name__)

#: ligament kinds in anatomical order (anterior to posterior), then the cables of a longer chain
LIGAMENT_ORDER = ("ALL", "PLL", "FL", "CL", "ITL", "ISL", "SSL")
#: load directions of a moment-rotation curve: both sides of lateral bending and axial rotation
CURVE_DIRECTIONS = ("flexion", "extension", "lateral_bending_right", "lateral_bending_left",
                    "axial_rotation_left", "axial_rotation_right")
#: project axis (0 lateral bending, 1 flexion-extension, 2 axial) and sign of each curve direction
AXIS_OF = {d: DIRECTIONS[d] for d in CURVE_DIRECTIONS}
#: a rotation change above this between two load steps 0.25 N*m apart is a jump (snap-through)
JUMP_DEG = 0.5


@dataclass
class LevelStructures:
    """The structures of one level of a model: which fibre groups, facet surfaces and disc belong to it."""

    level: str
    upper: int                      # free-body index of the level's upper vertebra
    disc: int                       # index into model.discs
    centre: np.ndarray              # (3,) disc centre, reference frame [m] (carried by the upper vertebra)
    groups: dict                    # ligament kind -> [fibre group ids]
    surfaces: dict                  # side -> facet surface id
    labels: list                    # structure labels in table order: disc, facet_left, facet_right, kinds


def level_structures(model: SpineModel, level: str, surface_sides: dict | None = None) -> LevelStructures:
    """The disc, facets and ligament groups of ``level`` in ``model`` (its fibre groups carry the level name).

    ``surface_sides``: {facet surface id: side} for the level's facet surfaces (an FSU's ``surface_side`` list,
    or the L2-S1 model's (level, side) pairs), default: every surface of a one-level model in the order added.
    """
    names = [d.name for d in model.discs]
    if level not in names:
        raise ValueError(f"model has no disc of level {level!r}; levels: {names}")
    di = names.index(level)
    spec = model.discs[di]
    if spec.upper < 0:
        raise ValueError(f"level {level!r}: its upper vertebra is fixed; no internal loads to report")
    groups: dict = {}
    for g, (_, kind, lv) in enumerate(model.fibre_groups):
        if lv == level and kind in LIGAMENT_ORDER:
            groups.setdefault(kind, []).append(g)
    if surface_sides is None:
        surface_sides = {i: s for i, s in enumerate(("left", "right")[: len(model.surfaces)])}
    surfaces = {side: sid for sid, side in surface_sides.items()}
    labels = ["disc"] + [f"facet_{s}" for s in ("left", "right") if s in surfaces] + \
             [k for k in LIGAMENT_ORDER if k in groups]
    return LevelStructures(level, spec.upper, di, np.asarray(spec.centre, float), groups, surfaces, labels)


def _about(x, R, body, centre_ref, c_body, F, M_ref):
    """Moment about the (moving) disc centre from a generalised force (F, moment about the body's reference point)."""
    p = x[:, body] + np.einsum("bij,j->bi", R[:, body], centre_ref - c_body)
    return M_ref + np.cross(x[:, body] - p, F)


def structure_loads(model: SpineModel, x, R, fmask=1.0, cmask=1.0, level: str | None = None,
                    structures: LevelStructures | None = None):
    """Force [N] and moment [N*m] (about the disc centre) that each structure of a level exerts on its upper vertebra.

    Returns ``(labels, F (B, S, 3), M (B, S, 3))`` in the project frame (world axes). The disc's force acts at the
    disc centre (its moment is its torque); facet and ligament contributions come from the model's own residual with
    every other element masked off (the same force laws, no second implementation).
    """
    st = structures or level_structures(model, level)
    B = x.shape[0]
    fm = np.broadcast_to(np.asarray(fmask, float), (B, model.nf)) if model.nf else np.zeros((B, 0))
    cm = np.broadcast_to(np.asarray(cmask, float), (B, model.nc)) if model.nc else np.zeros((B, 0))
    b = st.upper
    cb = model.c[b]
    F = np.zeros((B, len(st.labels), 3))
    M = np.zeros((B, len(st.labels), 3))
    # disc: force on the upper body at the disc centre, torque on the upper body (both world axes)
    spec = model.discs[st.disc]
    dl = model.disc_loads(x, R)
    RB = R[:, spec.lower] if spec.lower >= 0 else np.broadcast_to(np.eye(3), (B, 3, 3))
    axes = np.einsum("bij,kj->bki", RB, spec.frame)          # disc frame rows in the world
    F[:, 0] = np.einsum("bk,bki->bi", dl["force"][:, st.disc], axes)
    M[:, 0] = np.einsum("bij,bj->bi", RB, dl["torque"][:, st.disc])
    base, _ = model.evaluate(x, R, None, np.zeros_like(fm), np.zeros_like(cm), jacobian=False)
    for j, lab in enumerate(st.labels[1:], start=1):
        fmj, cmj = np.zeros_like(fm), np.zeros_like(cm)
        if lab.startswith("facet_"):
            sel = model.k_surf == st.surfaces[lab[6:]]
            cmj[:, sel] = cm[:, sel]
        else:
            sel = np.isin(model.f_group, st.groups[lab])
            fmj[:, sel] = fm[:, sel]
        Q, _ = model.evaluate(x, R, None, fmj, cmj, jacobian=False)
        d = Q[:, b] - base[:, b]
        F[:, j] = d[:, :3]
        M[:, j] = _about(x, R, b, st.centre, cb, d[:, :3], d[:, 3:])
    return list(st.labels), F, M


def applied_about_centre(model: SpineModel, x, R, loads, structures: LevelStructures):
    """The external loads on the level's upper vertebra as (F, M about the disc centre) (B, 3) each."""
    L = np.asarray(loads, float)
    b = structures.upper
    return L[:, b, :3], _about(x, R, b, structures.centre, model.c[b], L[:, b, :3], L[:, b, 3:])


def balance_residual(model, x, R, loads, fmask, cmask, structures: LevelStructures):
    """max |sum of the structures' moments + the applied moment| [N*m] per scenario of a one-level unit (its upper
    vertebra carries only the level's structures and the external load): 0 at an equilibrium."""
    _, F, M = structure_loads(model, x, R, fmask, cmask, structures=structures)
    Fa, Ma = applied_about_centre(model, x, R, loads, structures)
    return np.maximum(np.abs(F.sum(1) + Fa).max(-1) * 0.05, np.abs(M.sum(1) + Ma).max(-1))


def _rotation_deg(R, R0, directions):
    rot = so3.log(R @ np.swapaxes(R0, -1, -2))
    ax = np.array([AXIS_OF[d][0] for d in directions])
    sg = np.array([AXIS_OF[d][1] for d in directions])
    return np.degrees(rot[np.arange(len(directions)), ax] * sg), np.degrees(rot)


def _loads_table(model, fsu: FSU, x, R, fmask, cmask, structures, loads):
    """Wide per-scenario table of internal loads at the level (N, N*m)."""
    labels, F, M = structure_loads(model, x, R, fmask, cmask, structures=structures)
    spec = model.discs[structures.disc]
    dl = model.disc_loads(x, R)
    out = {}
    out["disc_axial_force_n"] = dl["force"][:, structures.disc, 2]           # + = compression (pushes the upper up)
    out["disc_shear_n"] = np.linalg.norm(dl["force"][:, structures.disc, :2], axis=-1)
    out["disc_shear_ap_n"] = dl["force"][:, structures.disc, 0]
    out["disc_shear_lat_n"] = dl["force"][:, structures.disc, 1]
    cf = model.contact_forces(x, R, cmask)
    off = model.contact_forces(x, R, cmask, beyond_extent=True)
    for side, sid in structures.surfaces.items():
        out[f"facet_{side}_contact_n"] = cf[:, sid]
    for side, sid in structures.surfaces.items():
        # the part carried by contact points beyond the fitted articular surface (Eq. 4 extrapolated there)
        out[f"facet_{side}_beyond_surface_n"] = off[:, sid]
    gf = model.group_forces(x, R, fmask)
    for kind, gs in structures.groups.items():
        out[f"{kind}_tension_n"] = gf[:, gs].sum(1)
    # moments about the disc centre, world axes: x lateral bending, y flexion-extension, z axial rotation
    for j, lab in enumerate(labels):
        for a, ax in enumerate(("x", "y", "z")):
            out[f"{lab}_moment_{ax}_nm"] = M[:, j, a]
    Fa, Ma = applied_about_centre(model, x, R, loads, structures)
    res = np.abs(M.sum(1) + Ma).max(-1)
    out["moment_balance_residual_nm"] = res
    _ = spec
    return pd.DataFrame(out)


def moment_rotation_curves(fsu: FSU, moments_nm=None, directions=CURVE_DIRECTIONS, stages=("intact",),
                           max_iter=80, tol=1e-8) -> pd.DataFrame:
    """Pure-moment curves of a unit, solved as a continuation, with the internal loads at every step.

    ``moments_nm`` default 0, 0.25, ..., 10 N*m. Every (stage, direction) is one scenario of one batch; step k
    starts from the equilibrium of step k-1 (the first from the stage's 0 N*m equilibrium). Columns: stage,
    direction, moment_nm, rotation_deg (about the loading axis, from the stage's 0 N*m state), rot_x/y/z_deg,
    converged, jump (rotation change from the previous step above :data:`JUMP_DEG`), rotation_from_first_rest_deg
    (the same rotation from the first stage's 0 N*m state, e.g. the intact unit's neutral position), and the
    internal loads of
    :func:`structure_loads` (tensions, facet contact forces, disc axial force and shear, moments about the disc
    centre per structure), ``facet_<side>_beyond_surface_n`` (the part of a facet's contact force from points outside
    the landmarks' extent of its Eq. 4 surface, where the regression is extrapolated) and ``moment_balance_residual_nm`` (|sum of the structures' moments + the applied
    moment|, 0 at an equilibrium).
    """
    m = fsu.model
    if moments_nm is None:
        moments_nm = np.round(np.arange(0.0, 10.0 + 1e-9, 0.25), 2)
    moments_nm = np.asarray(moments_nm, float)
    if moments_nm[0] != 0.0 or np.any(np.diff(moments_nm) <= 0):
        raise ValueError("moments_nm must start at 0 and increase")
    stages, directions = list(stages), list(directions)
    grid = [(s, d) for s in stages for d in directions]
    fm_s, cm_s = fsu.masks(stages)
    si = np.array([stages.index(s) for s, _ in grid])
    fm, cm = fm_s[si], cm_s[si]
    path = np.stack([moment_loads([d for _, d in grid], [M] * len(grid), m.nb) for M in moments_nm])
    # the stages' rest states first: one a saddle hides (solve.continue_rest_states) is continued from the stage
    # before; a rest state reached from the reference is the start of its curves unchanged (its step 0 converges at
    # once)
    r0 = solve(m, np.zeros((len(stages), m.nb, 6)), fmask=fm_s, cmask=cm_s, max_iter=max_iter, tol_force=tol,
               tol_moment=tol)
    if not r0.converged.all():
        r0 = continue_rest_states(m, r0, fm_s, cm_s, max_iter=max_iter, tol_force=tol, tol_moment=tol)
    start = [(r0.x[i], r0.R[i]) if r0.converged[i] else m.reference_state(1) for i in range(len(stages))]
    x0 = np.stack([np.reshape(start[i][0], (m.nb, 3)) for i in si])
    R0 = np.stack([np.reshape(start[i][1], (m.nb, 3, 3)) for i in si])
    steps = solve_sequence(m, path, x0=x0, R0=R0, fmask=fm, cmask=cm, max_iter=max_iter, tol_force=tol,
                           tol_moment=tol)
    st = level_structures(m, fsu.level.name, dict(enumerate(fsu.surface_side)))
    R0 = steps[0].R[:, 0]
    R_first = np.repeat(R0[[0]], len(grid), axis=0)      # the rest state of stages[0] (same for every direction)
    rows = []
    prev = None
    for k, (M, res) in enumerate(zip(moments_nm, steps)):
        rot, rvec = _rotation_deg(res.R[:, 0], R0, [d for _, d in grid])
        tab = _loads_table(m, fsu, res.x, res.R, fm, cm, st, path[k])
        tab.insert(0, "stage", [s for s, _ in grid])
        tab.insert(1, "direction", [d for _, d in grid])
        tab.insert(2, "moment_nm", float(M))
        tab.insert(3, "rotation_deg", rot)
        tab.insert(4, "rot_x_deg", rvec[:, 0])
        tab.insert(5, "rot_y_deg", rvec[:, 1])
        tab.insert(6, "rot_z_deg", rvec[:, 2])
        tab.insert(7, "converged", res.converged)
        tab.insert(8, "jump", np.zeros(len(grid), bool) if prev is None else np.abs(rot - prev) >= JUMP_DEG)
        # the same rotation measured from the first stage's rest state (the intact unit's neutral position): a
        # removed pre-tensioned structure moves the stage's own rest state, from which rotation_deg is measured
        tab.insert(9, "rotation_from_first_rest_deg", _rotation_deg(res.R[:, 0], R_first, [d for _, d in grid])[0])
        prev = rot
        rows.append(tab)
    df = pd.concat(rows, ignore_index=True)
    df = df.sort_values(["stage", "direction", "moment_nm"], key=lambda c: c.map(
        {**{s: i for i, s in enumerate(stages)}, **{d: i for i, d in enumerate(directions)}}) if c.name != "moment_nm"
        else c, kind="stable").reset_index(drop=True)
    bad = ~df["converged"]
    if bad.any():
        log.info("moment-rotation curves: %d of %d steps did not converge (flagged converged=False)",
                    int(bad.sum()), len(df))
    return df


def axial_compression_curve(fsu_with_cable: FSU, cable_group: int | None = None, forces_n=None, max_iter=80,
                            tol=1e-8) -> pd.DataFrame:
    """Follower load (0-1000 N by default, 50 N steps) on a unit built with ``build_fsu(..., follower=True)`` (a
    constant-tension cable along the disc normal through the disc centre whose mask weight is the force in N;
    ``cable_group`` default: the unit's ``follower_group``). Columns: force_n,
    converged, disc axial force, facet contact forces, ligament tensions, each structure's force along the disc normal
    and the disc's and the facets' shares of the compression crossing the joint (disc + facets)."""
    m = fsu_with_cable.model
    cable_group = fsu_with_cable.follower_group if cable_group is None else cable_group
    if cable_group is None:
        raise ValueError("axial_compression_curve: the unit has no follower cable (build_fsu(..., follower=True))")
    if forces_n is None:
        forces_n = np.arange(0.0, 1000.0 + 1e-9, 50.0)
    forces_n = np.asarray(forces_n, float)
    cab = m.f_group == cable_group
    base = fsu_with_cable.masks(["intact"])[0]
    fmask_path = []
    for f in forces_n:
        fmk = base.copy()
        fmk[:, cab] = f
        fmask_path.append(fmk)
    zero = np.zeros((1, m.nb, 6))
    steps = solve_sequence(m, np.stack([zero] * len(forces_n)), fmask=np.stack(fmask_path), max_iter=max_iter,
                           tol_force=tol, tol_moment=tol)
    st = level_structures(m, fsu_with_cable.level.name, dict(enumerate(fsu_with_cable.surface_side)))
    n_world = disc_frame(fsu_with_cable.level.disc_normal)[2]
    rows = []
    for f, res, fmk in zip(forces_n, steps, fmask_path):
        labels, F, _ = structure_loads(m, res.x, res.R, fmk, 1.0, structures=st)
        tab = _loads_table(m, fsu_with_cable, res.x, res.R, fmk, 1.0, st, zero)
        tab.insert(0, "force_n", float(f))
        tab.insert(1, "converged", res.converged)
        # compressive components along the disc normal carried by each structure (the cable pushes the upper
        # vertebra down; the structures push it up): shares of the applied force
        up = F @ n_world
        for j, lab in enumerate(labels):
            tab[f"{lab}_axial_n"] = up[:, j]
        # shares of the compression that crosses the joint (disc + facets: the ligaments' pre-tension adds to the
        # applied load), as Adams & Hutton (1980) state theirs ("of the intervertebral compressive force")
        fac = sum(up[:, j] for j, lab in enumerate(labels) if lab.startswith("facet_"))
        comp_total = np.clip(up[:, 0], 0.0, None) + np.clip(fac, 0.0, None)
        with np.errstate(invalid="ignore", divide="ignore"):
            tab["facet_share"] = np.where(comp_total > 0, np.clip(fac, 0.0, None) / comp_total, np.nan)
            tab["disc_share"] = np.where(comp_total > 0, np.clip(up[:, 0], 0.0, None) / comp_total, np.nan)
        rows.append(tab)
    return pd.concat(rows, ignore_index=True)


# ------------------------------------------------------------------ summaries (figures: lumbar.plots.load_sharing)
#: the moment component [axis] about which each curve direction is loaded, and the sign of "resisting"
_RESIST = {d: ("xyz"[AXIS_OF[d][0]], AXIS_OF[d][1]) for d in CURVE_DIRECTIONS}



def moment_shares(curves: pd.DataFrame) -> pd.DataFrame:
    """Long table: stage, direction, moment_nm, structure, moment_nm_resisted (the structure's moment about the
    loading axis that opposes the applied moment, N*m) and share (of the applied moment; the shares of a converged
    step add up to 1)."""
    rows = []
    labels = [c[: -len("_moment_x_nm")] for c in curves.columns if c.endswith("_moment_x_nm")]
    for r in curves.itertuples(index=False):
        ax, sign = _RESIST[r.direction]
        for lab in labels:
            v = -sign * getattr(r, f"{lab}_moment_{ax}_nm")
            rows.append({"stage": r.stage, "direction": r.direction, "moment_nm": r.moment_nm, "structure": lab,
                         "moment_resisted_nm": v, "share": v / r.moment_nm if r.moment_nm > 0 else np.nan})
    return pd.DataFrame(rows)


def summary_at(curves: pd.DataFrame, set_name: str, moment_nm=10.0) -> pd.DataFrame:
    """One row per (stage, direction) at ``moment_nm``: rotation, each structure's share of the moment, the facet
    contact forces, ligament tensions and disc axial force; and the unloaded state (moment 0) of each stage."""
    sh = moment_shares(curves[np.isclose(curves["moment_nm"], moment_nm)])
    wide = sh.pivot_table(index=["stage", "direction"], columns="structure", values="share", sort=False)
    wide.columns = [f"{c}_share" for c in wide.columns]
    at = curves[np.isclose(curves["moment_nm"], moment_nm)].set_index(["stage", "direction"])
    keep = ["rotation_deg", "converged"] + [c for c in curves.columns if c.endswith(("_contact_n", "_tension_n"))] + \
        ["disc_axial_force_n"]
    out = at[keep].join(wide).reset_index()
    out.insert(0, "set", set_name)
    out.insert(3, "moment_nm", moment_nm)
    return out


#: the posterior structures of the stepwise reduction, in the order the experiment removes them
POSTERIOR_REMOVAL = ("intact", "wo_ssl", "wo_isl", "wo_fl", "wo_cl")


def reduction_flexion(curves: pd.DataFrame, moment_nm=10.0, stages=POSTERIOR_REMOVAL) -> pd.DataFrame:
    """Flexion at ``moment_nm`` of every characteristic set along the removal of the posterior ligaments (SSL to
    CL): the rotation from each stage's own rest state (the ROM of the stepwise-reduction tables) and from the
    first stage's (the intact unit's neutral position), and whether each step increases it. The two differ where a
    removed pre-tensioned ligament moves the rest state: what removing a ligament does, read both ways."""
    rows = []
    for name, cv in curves.groupby("set", sort=False):
        f = cv[(cv["direction"] == "flexion") & np.isclose(cv["moment_nm"].astype(float), moment_nm)]
        prev = None
        for st in stages:
            g = f[f["stage"] == st]
            if g.empty:
                continue
            r = g.iloc[0]
            own = float(r["rotation_deg"]) if bool(r["converged"]) else np.nan
            first = float(r.get("rotation_from_first_rest_deg", np.nan)) if bool(r["converged"]) else np.nan
            rows.append({"set": name, "stage": st, "moment_nm": moment_nm, "rom_from_stage_rest_deg": own,
                         "rotation_from_intact_rest_deg": first,
                         "increases_from_stage_rest": None if prev is None else bool(own > prev[0]),
                         "increases_from_intact_rest": None if prev is None else bool(first > prev[1])})
            prev = (own, first)
    return pd.DataFrame(rows)


def cable_load_paths(idp: pd.DataFrame) -> pd.DataFrame:
    """Where the wire-cable forces go at L4-L5 (Table 5 scenarios): per muscle set-up and load case, the total cable
    tension and the compression carried by the disc, the facets and the ligaments (force along the disc normal on
    L4 [N]; ligaments negative: they pull) and the disc's and facets' shares of the compression they carry."""
    ax = [c for c in idp.columns if c.endswith("_axial_n") and c not in ("disc_axial_force_n",)]
    if not ax:
        raise ValueError("the L2-S1 table has no *_axial_n columns (lumbar.experiments.l2s1.internal_loads)")
    out = idp[["set", "muscle_setup", "load_case", "converged", "cable_total_n", "idp_mpa"]].copy()
    out["disc_n"] = idp["disc_axial_n"]
    fac = [c for c in ax if c.startswith("facet_")]
    lig = [c for c in ax if c not in fac and c != "disc_axial_n"]
    out["facets_n"] = idp[fac].sum(axis=1)
    out["ligaments_n"] = idp[lig].sum(axis=1)
    # the compression crossing the level is carried by the disc and the facets (ligaments pull: negative); their
    # shares are of that compression (with no cable the level still carries the ligaments' pre-tension)
    comp = out["disc_n"].clip(lower=0.0) + out["facets_n"].clip(lower=0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        for k in ("disc", "facets"):
            out[f"{k}_share"] = np.where(comp > 1e-9, out[f"{k}_n"].clip(lower=0.0) / comp, np.nan)
    for c in ax:
        out[c.replace("_axial_n", "_n")] = idp[c]
    return out
