"""The L2-S1 lumbar spine with wire-cable muscles (paper 1, Sects. 2.1.2, 2.3, 3.2, Appendix 3).

Model: sacrum (S1) fixed, L2..L5 free (24 DOF); every level L2-L3..L5-S1 gets disc, facet joints and
ligaments through :func:`lumbar.experiments.fsu.add_level` with the same characteristic set (the L4-L5 calibration
transferred unchanged, as the paper does). Five symmetric pairs of constant, length-independent cable
forces (Wilke et al. 1996: 80 N per pair, 40 N per side) pull L2 along lines of action derived from the
Christophy muscle set shipped with myo-sim (``data/cables/wilke1996_cables.csv`` says which fascicles and
how; the MJCF is read from site-packages at run time). Each cable is a ``law="cable"`` fibre from its
attachment on the vertebra to a fixed point ``cable_length_m`` away along its line of action (the pulley).

Scenarios: 7 muscle set-ups (none, each pair alone, all) x 7 load cases (neutral, +-3.75 N*m pure moment
on L2 in flexion/extension, lateral bending left/right, axial rotation left/right) = 49, solved as one
batch (cables switched by the per-scenario fibre mask, moments as loads).
"""
from __future__ import annotations

import functools
import hashlib
import logging
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..inputs import resources, tables
from .fsu import DIRECTIONS, add_level
from .load_sharing import level_structures, structure_loads
from ..geometry import load_geometry
from ..geometry import myo_sim as M
from ..geometry.myo_sim import BODY_OF
from ..mechanics.idp import FORMULAS, idp_from_disc
from ..inputs.io import TableError, read_table
from ..mechanics.model import GROUND, SpineModel
from ..mechanics.solve import solve
from ..inputs.tables import CABLES, IDP_INVITRO, L2S1_FREE, L2S1_MUSCLES, LOAD_CASES, MUSCLE_SETUPS

log = logging.getLogger(__name__)

LEVELS = ("L2-L3", "L3-L4", "L4-L5", "L5-S1")
FREE = L2S1_FREE
IDP_LEVEL = "L4-L5"
MUSCLES = L2S1_MUSCLES
MOMENT_NM = 3.75
CABLE_LENGTH_M = 1.0
# Newton step limits for the L2-S1 chain: its vertebrae move up to ~2 cm under the cables, so the FSU
# defaults (1 mm, 0.05 rad per iteration) cost many iterations; these were the fastest robust choice
# over the six characteristic sets (benchmarks/bench_l2s1.py).
STEP_LIMITS = dict(max_step_trans=1e-2, max_step_rot=0.1)
SIDES = {"left": "l", "right": "r"}


def default_cable_table() -> Path:
    return resources.data_dir() / "cables" / "wilke1996_cables.csv"


# ------------------------------------------------------------------ Christophy fascicles in myo-sim
@functools.lru_cache(maxsize=2)
def christophy_sites(chain_xml: str | None = None):
    """({site: (myo-sim body, position (3,) in the project frame [m])}, {tendon: [site, ...]}).

    Read from the myo-sim torso MJCF at qpos0 with the same frame conversion as the meshes
    (:mod:`lumbar.geometry.myo_sim`). Wrapping side-sites (inside ``<geom>``) are not path points.
    """

    p = Path(chain_xml) if chain_xml else M.chain_path()
    root = ET.parse(p).getroot()
    sites = {}

    for body, R, t in M.body_poses(root, p):
        for site in body.findall("site"):
            sites[site.get("name")] = (body.get("name"),
                                       M.R_PROJECT_FROM_WORLD @ (t + R @ M.mjcf_vector(site, "pos", [0, 0, 0])))
    tendons = {}
    tfile = p.parent / "myotorso_tendon.xml"
    for sp in ET.parse(tfile).getroot().iter("spatial"):
        tendons[sp.get("name")] = [s.get("site") for s in sp.findall("site")]
    return sites, tendons


def _fascicle_path(name, side, sites, tendons):
    key = f"{name}_{SIDES[side]}_tendon"
    if key not in tendons:
        raise ValueError(f"{default_cable_table()}: fascicle {name!r} ({key}) not in the myo-sim torso MJCF")
    return [sites[s] for s in tendons[key]]


def derive_cables(table=None, tension_scale=1.0) -> pd.DataFrame:
    """Cable attachments and lines of action derived from the myo-sim Christophy fascicles.

    One row per cable (muscle set-up x side): attachment in the *myo-sim* frame [m], the myo-sim
    centroid of the vertebra it is attached to, unit direction, tension [N].
    Rules: attachment = mean of the listed fascicles' sites on the vertebra; direction = mean of the
    unit vectors from that site to the next path point (``..._to_next_site``), or from each fascicle's
    caudal path point to its cranial one (``..._caudal_site_to_cranial_site``), normalised.
    """

    path = Path(table) if table is not None else default_cable_table()
    df = read_table(path, CABLES)
    missing = sorted(set(MUSCLES) - set(df["muscle_setup"]))
    if missing or df["muscle_setup"].duplicated().any():
        raise TableError(path, f"need each muscle set-up once; missing {missing}", column="muscle_setup",
                         expected=", ".join(MUSCLES))
    sites, tendons = christophy_sites()
    myo = _myo_centroids()
    rows = []
    for i, r in df.iterrows():
        body = BODY_OF[r["vertebra"]]
        for side in ("left", "right"):
            att, dirs = [], []
            for fas in r["attachment_fascicles"].split(";"):
                pts = _fascicle_path(fas.strip(), side, sites, tendons)
                on = [k for k, (b, _) in enumerate(pts) if b == body]
                if not on:
                    raise TableError(path, f"fascicle {fas!r} has no site on {body}", row=i + 1,
                                     column="attachment_fascicles", expected=f"fascicles attached to {r['vertebra']}")
                att.append(pts[on[0]][1])
            for fas in r["direction_fascicles"].split(";"):
                pts = _fascicle_path(fas.strip(), side, sites, tendons)
                if r["direction_rule"] == "mean_unit_from_vertebra_site_to_next_site":
                    k = next(k for k, (b, _) in enumerate(pts) if b == body)
                    other = pts[k + 1] if k + 1 < len(pts) else pts[k - 1]
                    d = other[1] - pts[k][1]
                else:
                    lo, hi = sorted((pts[0][1], pts[-1][1]), key=lambda p: p[2])
                    d = hi - lo
                dirs.append(d / np.linalg.norm(d))
            u = np.mean(dirs, axis=0)
            u /= np.linalg.norm(u)
            a = np.mean(att, axis=0)
            rows.append(dict(muscle_setup=r["muscle_setup"], side=side, vertebra=r["vertebra"],
                             attach_x_m=a[0], attach_y_m=a[1], attach_z_m=a[2],
                             dir_x=u[0], dir_y=u[1], dir_z=u[2],
                             centroid_x_m=myo[r["vertebra"]][0], centroid_y_m=myo[r["vertebra"]][1],
                             centroid_z_m=myo[r["vertebra"]][2],
                             tension_n=float(r["tension_per_side"]) * tension_scale,
                             fascicles=r["attachment_fascicles"], direction_fascicles=r["direction_fascicles"],
                             rule=f"{r['attachment_rule']}; {r['direction_rule']}",
                             source=f"myo-sim {M.package_version()} (Apache-2.0), Christophy et al. 2012 fascicles; "
                                    "Wilke et al. 1996 cable concept",
                             kind="derived_from_geometry"))
    return pd.DataFrame(rows)


@functools.lru_cache(maxsize=1)
def _myo_centroids():
    g = load_geometry("default", levels=list(LEVELS))
    return {v: np.asarray(g.vertebrae[v].centroid, float) for v in FREE}


@functools.lru_cache(maxsize=1)
def _myo_meshes():
    g = load_geometry("myo_sim", levels=list(LEVELS))
    return {v: g.vertebrae[v].mesh for v in FREE}


_REGISTRATIONS: dict = {}    # (geometry name, vertebra, fingerprint of both meshes and centroids) -> (M, rms)


def vertebra_registration(geometry, v, source_centroid):
    """``register_vertebra`` of the myo-sim vertebra ``v`` onto ``geometry``'s one, computed once per mesh pair
    (cached by a fingerprint of both meshes and the starting centroids). A geometry with a ``similarity``
    (nominal, T) (a virtual specimen: its meshes are the nominal ones scaled by T) gets the nominal registration
    carried by T, ``(T @ M, s * rms)``: the same cable attachments on the nominal bone, scaled with it, instead
    of an ICP that would end elsewhere within its tolerance for every specimen."""
    if geometry.similarity is not None:
        base, T = geometry.similarity
        M, rms = vertebra_registration(base, v, source_centroid)
        return T @ M, rms * float(np.cbrt(np.linalg.det(T[:3, :3])))
    src, tgt = _myo_meshes()[v], geometry.vertebrae[v].mesh
    c = np.asarray(geometry.vertebrae[v].centroid, float)
    h = hashlib.sha1()
    for a in (src.vertices, src.faces, tgt.vertices, tgt.faces, np.asarray(source_centroid, float), c):
        h.update(np.ascontiguousarray(a).tobytes())
    key = (geometry.name, v, h.hexdigest())
    if key not in _REGISTRATIONS:
        _REGISTRATIONS[key] = register_vertebra(src, tgt, source_centroid, c)
    M, rms = _REGISTRATIONS[key]
    return M.copy(), rms


def register_vertebra(source_mesh, target_mesh, source_centroid, target_centroid, n_points=1500):
    """Similarity transform (4x4: rotation, uniform scale, translation) taking the myo-sim vertebra onto the
    target geometry's vertebra: ICP (trimesh.registration.icp, scale allowed, no reflection) from every k-th
    source vertex, started at the translation of the body centroids. Returns (matrix, rms [m]).
    Deterministic (no random sampling) on one machine; its fixed point moves with round-off (the closest-point
    pairs change discretely): OpenBLAS's Haswell and SkylakeX kernels gave matrices that differ by 2e-5 to 7e-4 and
    Table 5 IDP values that differ by up to 2e-4 relative (tests/test_results_identity.py, RTOL_REGISTRATION)."""
    v = np.asarray(source_mesh.vertices)
    pts = v[:: max(1, len(v) // n_points)]
    T0 = np.eye(4)
    T0[:3, 3] = np.asarray(target_centroid, float) - np.asarray(source_centroid, float)
    import trimesh  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    M, _, _ = trimesh.registration.icp(pts, target_mesh, initial=T0, threshold=1e-9, max_iterations=40,
                                       reflection=False, scale=True)
    moved = pts @ M[:3, :3].T + M[:3, 3]
    d = trimesh.proximity.closest_point(target_mesh, moved)[1]
    return M, float(np.sqrt(np.mean(d ** 2)))


def mirror_cables(cables: pd.DataFrame, about_y=0.0) -> pd.DataFrame:
    """Cables with every left cable replaced by the mirror image (y -> 2*about_y - y) of its right one."""
    out = cables.copy()
    for ms in out["muscle_setup"].unique():
        r = out.index[(out["muscle_setup"] == ms) & (out["side"] == "right")][0]
        left = out.index[(out["muscle_setup"] == ms) & (out["side"] == "left")][0]
        for c in out.columns:
            out.at[left, c] = out.at[r, c] if c != "side" else "left"
        out.at[left, "attach_y_m"] = 2 * about_y - out.at[r, "attach_y_m"]
        out.at[left, "centroid_y_m"] = 2 * about_y - out.at[r, "centroid_y_m"]
        out.at[left, "dir_y"] = -out.at[r, "dir_y"]
    return out


# ------------------------------------------------------------------ model
@dataclass
class L2S1:
    model: SpineModel
    geometry: object
    charset: object
    cables: pd.DataFrame          # derived cables with the attachment used in this geometry
    cable_group: dict             # (muscle_setup, side) -> fibre group id
    group_kind: list              # kind per fibre group ("cable" for cables)
    surface_side: list            # (level, side) per facet surface

    def fmask(self, setups) -> np.ndarray:
        m = self.model
        out = np.ones((len(setups), m.nf))
        is_cable = np.array([self.group_kind[g] == "cable" for g in m.f_group])
        for i, s in enumerate(setups):
            if s not in MUSCLE_SETUPS:
                raise ValueError(f"unknown muscle_setup {s!r}; expected one of {MUSCLE_SETUPS}")
            on = set(MUSCLES) if s == "all" else ({s} if s != "none" else set())
            gids = [g for (ms, _), g in self.cable_group.items() if ms in on]
            out[i, is_cable] = np.isin(m.f_group[is_cable], gids).astype(float)
        return out


def build_l2s1(geometry, charset, cables: pd.DataFrame | None = None, facet_stiffness_n_per_m=None,
               disc_shear_stiffness_n_per_m=None,
               cable_length_m=CABLE_LENGTH_M, contact_eps=5e-5, slack_width_pct=0.5,
               registration="auto") -> L2S1:
    """L2-S1 model of ``geometry`` with ``charset`` at every level and the derived cables.

    Cable attachments and lines of action are defined on the myo-sim vertebrae (Christophy fascicles).
    On another geometry they are carried over by registering the myo-sim vertebra onto the geometry's one
    (``register_vertebra``: ICP with rotation, uniform scale and translation, started at the centroid
    translation); ``registration="translation"`` keeps the former rule ``a = c_geo + (a_myo - c_myo)``;
    "auto" (default) = ICP for Visible Human geometries (and their virtual specimens), translation otherwise
    (identity on myo-sim itself; synthetic test chains have no anatomical meshes to register).
    The table gains ``registration``, ``registration_scale`` and ``registration_rms_mm`` columns.
    """
    miss = [lv for lv in LEVELS if lv not in geometry.levels]
    if miss:
        raise ValueError(f"geometry {geometry.name!r} lacks level(s) {miss}; L2-S1 needs {list(LEVELS)}")
    if cables is None:
        cables = derive_cables()
    m = SpineModel(contact_eps=contact_eps, slack_width_pct=slack_width_pct)
    for v in FREE:
        m.add_body(v, geometry.vertebrae[v].centroid)
    m.add_body("S1", geometry.vertebrae["S1"].centroid, fixed=True)
    kinds, sides = [], []
    for lv in LEVELS:
        k, s = add_level(m, geometry.levels[lv], charset, facet_stiffness_n_per_m, disc_shear_stiffness_n_per_m)
        kinds += k
        sides += [(lv, x) for x in s]
    cab = cables.copy()
    groups = {}
    reg = {}
    if registration not in ("auto", "icp", "translation"):
        raise ValueError(f"registration {registration!r}; expected 'auto', 'icp' or 'translation'")
    if registration == "auto":
        registration = "icp" if str(geometry.name).startswith("visible_human") else "translation"
    for v in sorted(set(cab["vertebra"])):
        if registration == "icp" and geometry.name != "myo_sim":
            r0 = cab[cab["vertebra"] == v].iloc[0]
            M, rms = vertebra_registration(geometry, v, (r0.centroid_x_m, r0.centroid_y_m, r0.centroid_z_m))
            reg[v] = (M, rms, "icp")
        else:
            reg[v] = (None, float("nan"), "translation" if geometry.name != "myo_sim" else "identity (myo_sim)")
    placed = []
    for _, r in cab.iterrows():
        c_geo = np.asarray(geometry.vertebrae[r["vertebra"]].centroid, float)
        M, rms, how = reg[r["vertebra"]]
        a_myo = np.array([r.attach_x_m, r.attach_y_m, r.attach_z_m])
        u = np.array([r.dir_x, r.dir_y, r.dir_z])
        if M is None:
            a = c_geo + (a_myo - np.array([r.centroid_x_m, r.centroid_y_m, r.centroid_z_m]))
            scale = 1.0
        else:
            a = M[:3, :3] @ a_myo + M[:3, 3]
            scale = float(np.cbrt(np.linalg.det(M[:3, :3])))
            u = M[:3, :3] @ u
            u = u / np.linalg.norm(u)
        placed.append((how, scale, rms * 1e3, *u, *a))
        gid = m.add_fibre_group(f"{r.muscle_setup}_{r.side}", "cable", "cable", m.body_index(r["vertebra"]),
                                GROUND, a[None], (a + cable_length_m * u)[None], 0.0, "cable",
                                (float(r.tension_n),))
        groups[(r.muscle_setup, r.side)] = gid
        kinds.append("cable")
    cols = ["registration", "registration_scale", "registration_rms_mm", "model_dir_x", "model_dir_y", "model_dir_z",
            "model_x_m", "model_y_m", "model_z_m"]
    placed = pd.DataFrame(placed, columns=cols, index=cab.index)   # per column (per-cell .loc was most of a build)
    for c in cols:
        cab[c] = placed[c]
    m.finalize()
    return L2S1(m, geometry, charset, cab, groups, kinds, sides)


def scenario_grid(setups=MUSCLE_SETUPS, load_cases=LOAD_CASES):
    return [(s, c) for s in setups for c in load_cases]


def scenario_loads(load_cases, nb, moment_nm=MOMENT_NM, body=0):
    L = np.zeros((len(load_cases), nb, 6))
    for i, c in enumerate(load_cases):
        if c == "neutral":
            continue
        if c not in DIRECTIONS:
            raise ValueError(f"unknown load_case {c!r}; expected one of {LOAD_CASES}")
        axis, sign = DIRECTIONS[c]
        L[i, body, 3 + axis] = sign * moment_nm
    return L


@dataclass
class Solution:
    spine: L2S1
    grid: list
    fmask: np.ndarray
    x: np.ndarray
    R: np.ndarray
    converged: np.ndarray
    residual_force: np.ndarray
    residual_moment: np.ndarray
    loads: np.ndarray


def solve_scenarios(spine: L2S1, setups=MUSCLE_SETUPS, load_cases=LOAD_CASES, moment_nm=MOMENT_NM,
                    load_steps=1, max_iter=50, tol_force=1e-8, tol_moment=1e-8) -> Solution:
    """All set-up x load-case scenarios of one model as one batch."""
    grid = scenario_grid(setups, load_cases)
    m = spine.model
    fm = spine.fmask([g[0] for g in grid])
    loads = scenario_loads([g[1] for g in grid], m.nb, moment_nm)
    res = solve(m, loads, fmask=fm, load_steps=load_steps, max_iter=max_iter, tol_force=tol_force,
                tol_moment=tol_moment, **STEP_LIMITS)
    return Solution(spine, grid, fm, res.x, res.R, res.converged, res.residual_force, res.residual_moment, loads)


def equilibrium_residual(sol: Solution):
    """Re-evaluated max |force| [N] and |moment| [N*m] residual of every free vertebra (B,)."""
    Q, _ = sol.spine.model.evaluate(sol.x, sol.R, sol.loads, sol.fmask, 1.0, jacobian=False)
    return np.abs(Q[..., :3]).max(axis=(1, 2)), np.abs(Q[..., 3:]).max(axis=(1, 2))


def fsu_sagittal_moment(sol: Solution, level=IDP_LEVEL) -> np.ndarray:
    """Sagittal moment [N*m] (+ = flexion) borne by the whole functional unit at ``level`` (disc, facets and
    ligaments together, as paper 2's 6-DOF spring), per scenario.

    Statics of the part above the level: the unit carries the external loads on the bodies above it (the
    applied pure moment on L2 and the cable forces), taken about the level's disc centre and projected on
    the disc's lateral axis (the flexion axis, moving with the lower vertebra). There is no gravity in the
    in-vitro L2-S1 test. Not the disc's own Eq. 3 torque: prestressed ligaments and facets share the moment.
    """
    sp, m = sol.spine, sol.spine.model
    d = next(dd for dd in m.discs if dd.name == level)
    up, lo = level.split("-")
    above = [m.body_index(v) for v in FREE[: FREE.index(up) + 1]]
    lower = m.body_index(lo) if lo in m.body_names else None
    B = sol.x.shape[0]
    if lower is not None:
        R_lo = sol.R[:, lower]
        c = sol.x[:, lower] + np.einsum("bij,j->bi", R_lo, d.centre - m.c[lower])
        axis = np.einsum("bij,j->bi", R_lo, d.frame[1])
    else:
        c = np.broadcast_to(d.centre, (B, 3))
        axis = np.broadcast_to(d.frame[1], (B, 3))
    M = np.zeros((B, 3))
    for b in above:                                        # applied loads (force at the body's reference point)
        F, T = sol.loads[:, b, :3], sol.loads[:, b, 3:]
        M += T + np.cross(sol.x[:, b] - c, F)
    length, strain, T, dT, dvec, dn, pa, pb = m.fibre_state(sol.x, sol.R, sol.fmask)
    cab = np.isin(m.f_a, above) & np.array([sp.group_kind[g] == "cable" for g in m.f_group])
    if cab.any():
        F = -(T[:, cab] / dn[:, cab])[..., None] * dvec[:, cab]   # force on the body (towards the ground point)
        M += np.cross(pa[:, cab] - c[:, None, :], F).sum(axis=1)
    return np.einsum("bi,bi->b", M, axis)


def internal_loads(sol: Solution, level=IDP_LEVEL) -> pd.DataFrame:
    """Per scenario: disc loads, facet forces and ligament group forces at ``level``; cable forces."""
    sp, m = sol.spine, sol.spine.model
    di = [d.name for d in m.discs].index(level)
    dl = m.disc_loads(sol.x, sol.R)
    F, T = dl["force"][:, di], dl["torque"][:, di]
    cf = m.contact_forces(sol.x, sol.R)
    gf = m.group_forces(sol.x, sol.R, sol.fmask)
    df = pd.DataFrame({
        "muscle_setup": [g[0] for g in sol.grid], "load_case": [g[1] for g in sol.grid],
        "converged": sol.converged,
        "disc_axial_force_n": F[:, 2], "disc_shear_ap_n": F[:, 0], "disc_shear_lat_n": F[:, 1],
        # moment carried by the disc (restoring torque on the upper body, sign flipped: + = the disc is
        # loaded in flexion / right lateral bending / left axial rotation)
        "disc_moment_lateral_nm": -T[:, 0], "disc_moment_sagittal_nm": -T[:, 1], "disc_moment_axial_nm": -T[:, 2],
        "disc_flexion_deg": np.degrees(dl["phi"][:, di, 1]),
        # moment borne by the whole unit (disc + facets + ligaments), paper 2's FSU moment
        "fsu_moment_sagittal_nm": fsu_sagittal_moment(sol, level),
    })
    for sid, (lv, side) in enumerate(sp.surface_side):
        if lv == level:
            df[f"facet_{side}_n"] = cf[:, sid]
    kinds = {}
    for g, (name, kind, lv) in enumerate(m.fibre_groups):
        if lv == level:
            kinds.setdefault(kind, []).append(g)
    for kind in ("ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL"):
        if kind in kinds:
            df[f"lig_{kind}_n"] = gf[:, kinds[kind]].sum(1)
    cab = [g for g, (_, kind, _) in enumerate(m.fibre_groups) if kind == "cable"]
    df["cable_total_n"] = gf[:, cab].sum(1) if cab else 0.0
    # where the load goes at this level: the force each structure exerts on the level's upper vertebra along the
    # disc normal (+ = pushes it up, i.e. carries compression) and its moments about the disc centre
    st = level_structures(m, level, {sid: side for sid, (lv, side) in enumerate(sp.surface_side) if lv == level})
    labels, F, M = structure_loads(m, sol.x, sol.R, sol.fmask, 1.0, structures=st)
    normal = np.einsum("bij,j->bi", sol.R[:, m.discs[di].lower], m.discs[di].frame[2]) \
        if m.discs[di].lower >= 0 else np.broadcast_to(m.discs[di].frame[2], (len(sol.x), 3))
    for j, lab in enumerate(labels):
        df[f"{lab}_axial_n"] = np.einsum("bi,bi->b", F[:, j], normal)
        df[f"{lab}_moment_y_nm"] = M[:, j, 1]
    return df


def run_set(geometry, charset, cables=None, idp_formula="paper1", idp_kwargs=None, facet_stiffness_n_per_m=None,
            disc_shear_stiffness_n_per_m=None, load_steps=1, max_iter=50, tol=1e-7, moment_nm=MOMENT_NM,
            specimen=False):
    """Build, solve the 49 scenarios, and return (internal-loads table with idp_mpa, Solution).

    Scenarios without equilibrium are flagged (``converged`` False, ``idp_mpa`` NaN) with a WARNING; for a virtual
    specimen (``specimen`` True), where the generator drops the specimen from that row and counts it, an INFO line."""
    if idp_formula not in FORMULAS:
        raise ValueError(f"unknown IDP formula {idp_formula!r} (config key l2s1.idp_formula); expected one of {FORMULAS}")
    sp = build_l2s1(geometry, charset, cables, facet_stiffness_n_per_m=facet_stiffness_n_per_m,
                    disc_shear_stiffness_n_per_m=disc_shear_stiffness_n_per_m)
    sol = solve_scenarios(sp, moment_nm=moment_nm, load_steps=load_steps, max_iter=max_iter, tol_force=tol,
                          tol_moment=tol)
    df = internal_loads(sol)
    csa = geometry.levels[IDP_LEVEL].disc_csa
    idp = idp_from_disc(df["disc_axial_force_n"].to_numpy(), df["fsu_moment_sagittal_nm"].to_numpy(),
                        formula=idp_formula, csa_m2=csa, **(idp_kwargs or {}))
    df.insert(3, "idp_mpa", np.where(sol.converged, idp / 1e6, np.nan))
    if not sol.converged.all():
        bad = [f"{a}/{b}" for (a, b), c in zip(sol.grid, sol.converged) if not c]
        log.log(logging.INFO if specimen else logging.WARNING,
                "L2-S1 %s%s: %d of %d scenarios did not converge (%s); idp_mpa NaN, flagged",
                getattr(charset, "name", "?"), " (virtual specimen)" if specimen else "", len(bad),
                len(bad) + int(sol.converged.sum()), ", ".join(bad))
    return df, sol


# ------------------------------------------------------------------ reference (measured/surrogate) IDP table
def read_idp_table(path) -> pd.DataFrame:
    """Validated measured/surrogate IDP table (schema in data/experiments/README.md)."""
    df = read_table(path, IDP_INVITRO)
    key = list(zip(df["muscle_setup"], df["load_case"]))
    dup = [i + 1 for i, k in enumerate(key) if key.index(k) != i]
    if dup:
        raise TableError(path, f"duplicate (muscle_setup, load_case) {key[dup[0] - 1]}", row=dup[0],
                         column="load_case", expected="each scenario once")
    missing = sorted(set(scenario_grid()) - set(key))
    if missing:
        raise TableError(path, f"{len(missing)} scenario(s) missing, e.g. {missing[0]}", column="muscle_setup",
                         expected="all 7 x 7 muscle_setup x load_case rows")
    return df


def synopsis(sim: pd.DataFrame, ref: pd.DataFrame) -> pd.DataFrame:
    """Table 5 rows: sim (set, muscle_setup, load_case, idp_mpa, converged) against the reference table."""
    r = ref.rename(columns={"kind": "data_kind"})[["muscle_setup", "load_case", "idp_mean_mpa", "idp_sd_mpa",
                                                   "data_kind"]]
    df = sim[["set", "muscle_setup", "load_case", "idp_mpa", "converged"]].rename(columns={"idp_mpa": "idp_sim_mpa"})
    df = df.merge(r, on=["muscle_setup", "load_case"], how="left", validate="many_to_one")
    inside = (df["idp_sim_mpa"] >= df["idp_mean_mpa"] - df["idp_sd_mpa"]) & \
             (df["idp_sim_mpa"] <= df["idp_mean_mpa"] + df["idp_sd_mpa"])
    df["outlier"] = ~(inside & df["converged"].astype(bool))
    return df[["set", "muscle_setup", "load_case", "idp_sim_mpa", "idp_mean_mpa", "idp_sd_mpa", "outlier",
               "converged", "data_kind"]]


def outlier_counts(syn: pd.DataFrame, published: pd.DataFrame | None = None) -> pd.DataFrame:
    g = syn.groupby("set", sort=False)
    out = pd.DataFrame({"set": list(g.groups),
                        "outliers": g["outlier"].apply(lambda s: int(s.astype(bool).sum())).to_numpy(),
                        "not_converged": g["converged"].apply(lambda s: int((~s.astype(bool)).sum())).to_numpy(),
                        "scenarios": g.size().to_numpy().astype(int)})
    out["data_kind"] = g["data_kind"].agg(lambda s: ";".join(sorted(set(s.astype(str))))).to_numpy()
    real = syn["data_kind"].astype(str) != "surrogate"
    out["n_scenarios_real"] = real.groupby(syn["set"], sort=False).sum().astype(int).to_numpy()
    out["n_outliers_real"] = (syn["outlier"].astype(bool) & real).groupby(syn["set"], sort=False).sum().astype(int).to_numpy()
    out["surrogate_comparison"] = np.where(out["data_kind"].astype(str).str.contains("surrogate"),
                                           "method check (round trip on virtual specimens)",
                                           "none: every reference row is measured or published")
    return out


PUBLISHED_KEY = {"calibrated": "outliers_idp_this_paper_model", "chazal1985": "outliers_idp_chazal1985",
                 "shirazi_adl1986": "outliers_idp_shirazi_adl1986", "white_panjabi1990": "outliers_idp_white_panjabi1990",
                 "nolte1990": "outliers_idp_nolte1990", "rupp2015": "outliers_idp_rupp2015"}


def versus_paper(counts: pd.DataFrame, published_csv=None) -> pd.DataFrame:
    """Outlier counts beside the paper's (Table 5 / Sect. 3.2), in the columns of
    :data:`lumbar.inputs.tables.VS_PAPER_COLUMNS`; empty paper columns if the file is absent."""
    return tables.versus_paper(counts, published_csv, PUBLISHED_KEY)


def with_bands(synopsis: pd.DataFrame, bands: pd.DataFrame, set_name="calibrated") -> pd.DataFrame:
    """The Table 5 synopsis with the 90 % posterior band of ``set_name``'s simulated IDP (idp_band_low_mpa,
    idp_band_high_mpa; NaN for the other sets and where no band was computed); the outlier count stays on the MAP."""
    out = synopsis.copy()
    out["idp_band_low_mpa"], out["idp_band_high_mpa"] = np.nan, np.nan
    if bands is None or not len(bands):
        return out
    key = ["muscle_setup", "load_case"]
    m = out[key].merge(bands[key + ["low90", "high90"]], on=key, how="left")
    sel = (out["set"] == set_name).to_numpy()
    out.loc[sel, "idp_band_low_mpa"] = m.loc[sel, "low90"].to_numpy()
    out.loc[sel, "idp_band_high_mpa"] = m.loc[sel, "high90"].to_numpy()
    return out
