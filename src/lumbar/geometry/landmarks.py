"""Rule-based landmarks (ligament insertions, facet surfaces) for meshes that carry none (myo-sim).

``propose_landmarks(meshes)`` is deterministic; its output is committed as
``data/landmarks/myo_sim_landmarks.csv`` and read back (and validated) at load time, so a user can edit it.
Regenerate with ``python -m lumbar.geometry.landmarks``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import trimesh

from ..inputs import resources
from .analysis import EZ, facing_endplate, inferior_endplate, sagittal_split
from .core import GeometryError, LEVEL_NAMES, level_vertebrae

COLUMNS = ["level", "structure", "side", "point_index", "x_m", "y_m", "z_m", "body", "vertex_index",
           "rule", "source", "kind"]
SURFACE_TOL_M = 1e-3
MM = 1e-3
ENDPLATE_RADIUS = 0.012
SIDES3 = (("left", 1.0), ("medial", 0.0), ("right", -1.0))
SIDE_SIGN = {"left": 1.0, "right": -1.0}


def _source(body: str, version: str) -> str:
    stl = "sacrum.stl" if body == "S1" else f"lumbar{body[1]}.stl"
    return f"myo-sim {version} {stl} (Apache-2.0), vertex chosen by rule"


class VertebraFeatures:
    """Per-vertebra reference features in the project frame."""

    def __init__(self, name, mesh, x_post=None, x_lam=None):
        self.name, self.mesh, self.v = name, mesh, np.asarray(mesh.vertices)
        xp, xl = sagittal_split(mesh)
        self.x_post = xp if x_post is None else x_post
        self.x_lam = xl if x_lam is None else x_lam
        self.body = self.v[self.v[:, 0] > self.x_post]
        self.arch = self.v[self.v[:, 0] < self.x_post - 2 * MM]


def _snap(v, target, used, mask=None, mesh=None):
    """Index of the candidate vertex (``mask``, not in ``used``) nearest to ``target``.

    If ``mesh`` is given, ``used`` is ignored and the landmark is instead the closest point to ``target``
    on the faces touching the candidate vertices (the myo-sim meshes have only ~200 vertices, too few for
    distinct, left/right-symmetric vertex insertions); returns (nearest candidate vertex index, point).
    """
    d = np.linalg.norm(v - target, axis=1)
    if mask is not None:
        d = np.where(mask, d, np.inf)
    if mesh is None:
        for i in used:
            d[i] = np.inf
    i = int(np.argmin(d))
    if not np.isfinite(d[i]):
        raise ValueError(f"no candidate vertex for landmark target {np.round(target, 4)}")
    if mesh is None:
        used.add(i)
        return i
    m = np.zeros(len(v), bool) if mask is None else np.asarray(mask, bool)
    faces = mesh.faces[np.any(m[mesh.faces], axis=1)]
    sub = trimesh.Trimesh(mesh.vertices, faces, process=False)
    p, _, _ = trimesh.proximity.closest_point(sub, np.atleast_2d(target))
    return i, np.asarray(p[0], dtype=float)


def _facet_clusters(fu: VertebraFeatures, fl: VertebraFeatures, s: float):
    vu, vl = fu.v, fl.v
    mu = (vu[:, 0] < fu.x_post - 2 * MM) & (s * vu[:, 1] > 8 * MM) & (s * vu[:, 1] < 30 * MM)
    iap = vu[mu & (vu[:, 2] < vu[mu, 2].min() + 10 * MM)]
    ml = (vl[:, 0] < fl.x_post - 2 * MM) & (s * vl[:, 1] > 8 * MM) & (s * vl[:, 1] < 30 * MM)
    sap = vl[ml & (vl[:, 2] > vl[ml, 2].max() - 10 * MM)]
    return iap, sap


LATERAL_LIMIT_DEG = 70.0   # joint direction fallback, see facet_grid


def facet_grid(fu, fl, s, step=3 * MM):
    """9 points on each articular surface of the joint on side ``s`` (+1 left, -1 right).

    Joint direction nj = horizontal direction from the upper vertebra's inferior-articular-process (IAP)
    vertex cluster to the lower vertebra's superior-articular-process (SAP) cluster; the joint plane is
    vertical and normal to nj, through the midpoint c of the clusters.  For each surface a 3x3 grid in that
    plane (horizontal pitch ``step``, vertical pitch min(step, 30 % of the cluster's height), centred at c
    horizontally and at the cluster's mean height) is projected on the surface by rays along +nj (SAP,
    medial face) or -nj (IAP, lateral face).  Where nj is more than ``LATERAL_LIMIT_DEG`` from the lateral
    direction, the clusters are not facing each other across the joint and nj = (0, s, 0) is used."""
    iap, sap = _facet_clusters(fu, fl, s)
    ci, cs = iap.mean(axis=0), sap.mean(axis=0)
    c = 0.5 * (ci + cs)
    nj = cs - ci
    nj[2] = 0.0
    if np.linalg.norm(nj) < 1e-4:
        nj = np.array([0.0, s, 0.0])
    nj /= np.linalg.norm(nj)
    if abs(nj[1]) < np.cos(np.radians(LATERAL_LIMIT_DEG)):
        # clusters separated antero-posteriorly rather than across the joint (myo-sim L1-L2: the coarse L1
        # IAP cluster lies 9 mm behind the L2 SAP cluster, which put the grids on a coronal plane and made
        # the two landmark sets overlap by up to 22 mm): use the pure lateral direction instead
        nj = np.array([0.0, float(s), 0.0])
    u = np.cross(EZ, nj)
    u /= np.linalg.norm(u)

    def grid(cluster):
        cz = np.array([c[0], c[1], cluster[:, 2].mean()])
        dz = min(step, 0.3 * np.ptp(cluster[:, 2]))
        return np.array([cz + a * step * u + b * dz * EZ for b in (1, 0, -1) for a in (-1, 0, 1)])

    sup = _ray_project(fl.mesh, grid(sap) - 6 * MM * nj, nj, s)     # lower vertebra SAP, its medial face
    inf = _ray_project(fu.mesh, grid(iap) + 6 * MM * nj, -nj, s)    # upper vertebra IAP, its lateral face
    return sup, inf, c, iap, sap


def _ray_project(mesh, origins, direction, side_sign):
    """First hit (on the joint's side, within 12 mm of the ray origin) of parallel rays on the mesh;
    closest surface point to the grid node where a ray misses."""
    out, _, _ = trimesh.proximity.closest_point(mesh, origins + 6 * MM * direction)
    out = np.asarray(out, dtype=float)
    dirs = np.tile(direction, (len(origins), 1))
    locs, ray_idx, _ = mesh.ray.intersects_location(origins, dirs, multiple_hits=True)
    for k in range(len(origins)):
        hits = locs[ray_idx == k]
        if len(hits):
            t = (hits - origins[k]) @ direction
            ok = (t > 0) & (t < 12 * MM) & (side_sign * hits[:, 1] > 4 * MM)
            if ok.any():
                out[k] = hits[np.argmin(np.where(ok, t, np.inf))]
    return out


def propose_landmarks(meshes: dict, version: str = "0.2.4") -> pd.DataFrame:
    """Deterministic rule-based landmarks for every level whose two vertebrae are in ``meshes``
    (project frame, metres).  Returns a DataFrame with columns ``COLUMNS``: per level, the endplate rims (ALL, PLL),
    the ligamentum flavum, the spinous processes (ISL, SSL), the transverse processes (ITL) and the facets with
    their capsules (CL), each structure's rule a function of its own."""
    rows = []
    feats = {}
    for v in ("L1", "L2", "L3", "L4", "L5"):
        if v in meshes:
            feats[v] = VertebraFeatures(v, meshes[v])
    if "S1" in meshes and "L5" in feats:
        f5 = feats["L5"]
        feats["S1"] = VertebraFeatures("S1", meshes["S1"], x_post=f5.x_post, x_lam=f5.x_lam)

    def add(level, structure, side, k, body, vidx, p, rule, kind="derived_from_geometry"):
        rows.append(dict(level=level, structure=structure, side=side, point_index=k,
                         x_m=float(p[0]), y_m=float(p[1]), z_m=float(p[2]), body=body,
                         vertex_index=int(vidx), rule=rule, source=_source(body, version), kind=kind))

    for level in LEVEL_NAMES:
        U, L = level_vertebrae(level)
        if U not in feats or L not in feats:
            continue
        fu, fl = feats[U], feats[L]
        c_inf, n_inf, _ = inferior_endplate(fu.mesh, fu.mesh.triangles_center[:, 0] > fu.x_post)
        c_sup, n_sup, _ = facing_endplate(fl.mesh, c_inf, n_inf, radius=ENDPLATE_RADIUS)
        _rim_landmarks(add, level, fu, fl, c_inf, n_inf, c_sup, n_sup)
        # lower-vertebra posterior candidates: no deeper than 30 mm below its superior endplate centre
        # (keeps the sacrum's posterior landmarks at the S1 segment; excludes lumbar inferior processes)
        zok = fl.v[:, 2] > c_sup[2] - 30 * MM
        _flavum_landmarks(add, level, fu, fl, zok)
        _spinous_landmarks(add, level, fu, fl, zok)
        _intertransverse_landmarks(add, level, fu, fl, c_sup)
        _facet_landmarks(add, level, fu, fl, zok)
    return pd.DataFrame(rows, columns=COLUMNS)


def _rim_landmarks(add, level, fu, fl, c_inf, n_inf, c_sup, n_sup):
    """Endplate rims (ALL anterior, PLL posterior), bands measured along the endplate normals."""
    U, L, vu, vl = fu.name, fl.name, fu.v, fl.v
    y0 = 0.0
    hu = (vu - c_inf) @ n_inf
    body_u = vu[:, 0] > fu.x_post
    band_u = body_u & (hu < hu[body_u].min() + 5 * MM)
    dl_ = vl - c_sup
    hl = dl_ @ n_sup
    rl = np.linalg.norm(dl_ - np.outer(hl, n_sup), axis=1)
    body_l = (vl[:, 0] > fl.x_post - 1 * MM) & (rl < 25 * MM)
    band_l = body_l & (hl > -4 * MM) & (hl < 3 * MM)
    if band_l.sum() < 8:  # coarse sacrum: widen the rim band to 10 mm below the endplate
        band_l = body_l & (hl > -10 * MM) & (hl < 3 * MM)
    for lig, half in (("ALL", 8 * MM), ("PLL", 5 * MM)):
        used_u, used_l = set(), set()   # fibres of one ligament use distinct vertices
        pick = np.argmax if lig == "ALL" else np.argmin
        ju = np.flatnonzero(band_u)[pick(vu[band_u, 0])]
        jl = np.flatnonzero(band_l)[pick(vl[band_l, 0])]
        where = "anterior" if lig == "ALL" else "posterior"
        for k, (side, sg) in enumerate(SIDES3):
            tu = np.array([vu[ju, 0], y0 + sg * half, vu[ju, 2]])
            iu, pu = _snap(vu, tu, used_u, band_u, mesh=fu.mesh)
            tl = np.array([vl[jl, 0], y0 + sg * half, vl[jl, 2]]) if L != "S1" else pu
            il, pl = _snap(vl, tl, used_l, band_l, mesh=fl.mesh)
            ru = (f"closest point, on the faces touching them, to the {U} vertebral body vertices within 5 mm (along the endplate normal) of its inferior endplate, "
                  f"of the {where}-most such vertex moved to y={sg * half * 1e3:+.0f} mm ({side})")
            rl_ = (f"closest point (on faces touching the candidates) of the {L} superior endplate rim vertices (within 4 mm below/3 mm above the endplate, 25 mm of its "
                   f"centre; coarse sacrum: 10 mm below) to the {where}-most such vertex moved to "
                   f"y={sg * half * 1e3:+.0f} mm ({side}); for S1 the rim vertex nearest to the upper end")
            add(level, lig, side, k, U, iu, pu, ru)
            add(level, lig, side, k, L, il, pl, rl_)


def _flavum_landmarks(add, level, fu, fl, zok):
    """Ligamentum flavum: inferior lamina edge of the upper vertebra -> superior lamina edge of the lower one."""
    U, L, vu, vl = fu.name, fl.name, fu.v, fl.v
    used_u, used_l = set(), set()
    for k, (side, sg) in enumerate(SIDES3):
        mu = (np.abs(vu[:, 1] - sg * 6 * MM) < 6 * MM) & (vu[:, 0] < fu.x_lam + 2 * MM) & (vu[:, 0] > fu.x_lam - 8 * MM)
        tu = np.array([fu.x_lam, sg * 6 * MM, vu[mu, 2].min()])
        iu = _snap(vu, tu, used_u, mu)
        ml = zok & (np.abs(vl[:, 1] - sg * 6 * MM) < 6 * MM) & (vl[:, 0] < fl.x_lam + 2 * MM) & (vl[:, 0] > fl.x_lam - 8 * MM)
        if not ml.any():  # sacrum: no lamina window; take its posterior arch near the midline
            ml = zok & (np.abs(vl[:, 1] - sg * 6 * MM) < 10 * MM) & (vl[:, 0] < fl.x_post - 2 * MM)
        tl = np.array([fl.x_lam, sg * 6 * MM, vl[ml, 2].max()])
        il = _snap(vl, tl, used_l, ml)
        add(level, "FL", side, k, U, iu, vu[iu],
            f"lowest vertex of the {U} lamina (0-8 mm behind the canal's posterior wall at the midline), "
            f"near y={sg * 6:+.0f} mm ({side})")
        add(level, "FL", side, k, L, il, vl[il],
            f"highest vertex of the {L} lamina (0-8 mm behind the canal's posterior wall; for S1 that of L5) no lower than 30 mm below the endplate, near y={sg * 6:+.0f} mm ({side})")


def _spinous_landmarks(add, level, fu, fl, zok):
    """Spinous processes: ISL (3 fibres along the process), SSL (tips)."""
    U, L, vu, vl = fu.name, fl.name, fu.v, fl.v
    mid_u = (np.abs(vu[:, 1]) < 5 * MM) & (vu[:, 0] < fu.x_lam - 3 * MM)
    mid_l = zok & (np.abs(vl[:, 1]) < 5 * MM) & (vl[:, 0] < fl.x_lam - 3 * MM)
    if mid_l.sum() < 4:  # coarse sacrum: whole posterior midline within 30 mm of the endplate
        mid_l = zok & (np.abs(vl[:, 1]) < 5 * MM) & (vl[:, 0] < fl.x_post - 2 * MM)
    used_u, used_l = set(), set()
    tip_u = vu[mid_u, 0].min()
    tip_l = vl[mid_l, 0].min() if mid_l.any() else tip_u
    for k, f in enumerate((0.25, 0.5, 0.75)):
        xu = fu.x_lam + f * (tip_u - fu.x_lam)
        iu = _snap(vu, np.array([xu, 0.0, vu[mid_u, 2].min()]), used_u, mid_u)
        xl_ = fl.x_lam + f * (tip_l - fl.x_lam)
        tl = np.array([xl_, 0.0, vl[mid_l, 2].max()]) if L != "S1" else vu[iu]
        il = _snap(vl, tl, used_l, mid_l)
        add(level, "ISL", "medial", k, U, iu, vu[iu],
            f"inferior edge of the {U} spinous process: midline vertex nearest to {int(f * 100)}% of the way "
            "from lamina to tip at the process's lowest z")
        add(level, "ISL", "medial", k, L, il, vl[il],
            f"superior edge of the {L} spinous process: midline vertex nearest to {int(f * 100)}% of the way "
            "from lamina to tip at the process's highest z (S1: sacral midline posterior vertex nearest to the upper end)")
    used_u, used_l = set(), set()
    iu = _snap(vu, np.array([tip_u, 0.0, vu[mid_u, 2].min()]), used_u, mid_u)
    il = _snap(vl, np.array([tip_l, 0.0, vl[mid_l, 2].max()]) if L != "S1" else vu[iu], used_l, mid_l)
    add(level, "SSL", "medial", 0, U, iu, vu[iu], f"posterior-inferior corner of the {U} spinous process tip")
    add(level, "SSL", "medial", 0, L, il, vl[il], f"posterior-superior corner of the {L} spinous process tip (S1: sacral midline posterior vertex nearest to the upper end)")


def _intertransverse_landmarks(add, level, fu, fl, c_sup):
    """Intertransverse ligaments: the lateral-most vertices of the transverse processes (the ala for S1)."""
    U, L, vu, vl = fu.name, fl.name, fu.v, fl.v
    for side, sg in SIDE_SIGN.items():
        name = "ITL_L" if sg > 0 else "ITL_R"
        used_u, used_l = set(), set()
        iu = _snap(vu, vu[np.argmax(sg * vu[:, 1])] + np.array([0, 0, -5 * MM]), used_u,
                   sg * vu[:, 1] > sg * vu[np.argmax(sg * vu[:, 1]), 1] - 5 * MM)
        ml = (vl[:, 2] > c_sup[2] - 25 * MM) & (vl[:, 0] < fl.x_post)
        jl = np.where(ml)[0][np.argmax(sg * vl[ml, 1])]
        il = _snap(vl, vl[jl] + np.array([0, 0, 5 * MM]), used_l,
                   ml & (sg * vl[:, 1] > sg * vl[jl, 1] - 5 * MM))
        add(level, name, side, 0, U, iu, vu[iu],
            f"{side} transverse process tip of {U}: lowest of the vertices within 5 mm of the most lateral one")
        add(level, name, side, 0, L, il, vl[il],
            f"{side} transverse process (ala for S1) tip of {L}: highest of the vertices within 5 mm of the "
            "most lateral posterior vertex within 25 mm below the endplate")


def _facet_landmarks(add, level, fu, fl, zok):
    """Facets (a 3x3 grid on each articular face) and their capsules (four rim fibres per side)."""
    U, L, vu, vl = fu.name, fl.name, fu.v, fl.v
    for side, sg in SIDE_SIGN.items():
        sup, inf, c, iap, sap = facet_grid(fu, fl, sg)
        for k in range(9):
            add(level, "facet_superior", side, k, L, -1, sup[k],
                f"{L} superior articular process, medial face: first surface hit of a ray cast laterally (along the "
                f"IAP->SAP cluster direction) from 6 mm medial of node {k} of a 3x3 grid (3 mm pitch, rows "
                "top->bottom, centred at the SAP cluster height) in the vertical joint plane through the midpoint "
                "of the IAP and SAP vertex clusters")
            add(level, "facet_inferior", side, k, U, -1, inf[k],
                f"{U} inferior articular process, lateral face: first surface hit of a ray cast medially from 6 mm "
                f"lateral of node {k} of the same 3x3 joint-plane grid")
        name = "CL_L" if sg > 0 else "CL_R"
        offs = [(0, 0, 6), (0, 0, -6), (-5, 0, 0), (5, 0, 0)]   # superior, inferior, posterior, anterior rim
        ui, li = set(), set()
        for k, o in enumerate(offs):
            t = c + np.array(o) * MM
            iu = _snap(vu, t, ui, (vu[:, 0] < fu.x_post - 2 * MM) & (sg * vu[:, 1] > 8 * MM))
            il = _snap(vl, t, li, zok & (vl[:, 0] < fl.x_post - 2 * MM) & (sg * vl[:, 1] > 8 * MM) & (sg * vl[:, 1] < 30 * MM))
            add(level, name, side, k, U, iu, vu[iu],
                f"{U} articular-process vertex nearest to the facet joint centre offset by {o} mm (x,y,z): "
                "capsule rim fibre")
            add(level, name, side, k, L, il, vl[il],
                f"{L} articular-process vertex nearest to the facet joint centre offset by {o} mm: capsule rim fibre")


def read_landmarks(path, meshes: dict) -> pd.DataFrame:
    """Read and validate a landmark CSV against meshes (project frame)."""
    p = Path(path)
    if not p.is_file():
        raise GeometryError(f"{p}: landmark CSV missing")
    try:
        header = list(pd.read_csv(p, nrows=0).columns)
    except Exception as exc:
        raise GeometryError(f"{p}: not readable as CSV ({exc})") from exc
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise GeometryError(f"{p}: missing column(s) {missing}; expected columns {COLUMNS}")
    from ..inputs.io import TableError, read_table  # noqa: PLC0415
    from ..inputs.tables import LANDMARKS  # noqa: PLC0415
    try:   # every cell: file, 1-based data row, column and expected form (metres, project frame)
        df = read_table(p, LANDMARKS)
    except TableError as exc:
        raise GeometryError(str(exc)) from None
    for body, sub in df.groupby("body"):
        if body not in meshes:
            continue
        pts = sub[["x_m", "y_m", "z_m"]].to_numpy()
        _, dist, _ = trimesh.proximity.closest_point(meshes[body], pts)
        if np.any(dist > SURFACE_TOL_M):
            j = int(np.argmax(dist > SURFACE_TOL_M))
            r = int(sub.index[j])
            raise GeometryError(
                f"{p}: row {r + 1} (level {sub['level'].iloc[j]}, {sub['structure'].iloc[j]}, body {body}) "
                f"columns x_m,y_m,z_m: point is {dist[j] * 1e3:.2f} mm from the {body} mesh surface; "
                f"expected within {SURFACE_TOL_M * 1e3:.0f} mm (metres, project frame)")
    return df


def landmarks_to_level_parts(df: pd.DataFrame, level: str, upper: str, lower: str):
    """Build (ligaments, facets) for one level from a landmark table."""
    from .core import FacetLandmarks, Ligament  # noqa: PLC0415
    sub = df[df["level"] == level]
    ligs, facets = [], {}
    for name in ("ALL", "PLL", "FL", "CL_L", "CL_R", "ISL", "SSL", "ITL_L", "ITL_R"):
        s = sub[sub["structure"] == name]
        if s.empty:
            continue
        up = s[s["body"] == upper].sort_values("point_index")
        lo = s[s["body"] == lower].sort_values("point_index")
        if list(up["point_index"]) != list(lo["point_index"]):
            raise GeometryError(f"landmarks {level} {name}: upper ({upper}) and lower ({lower}) fibre ends "
                                "do not pair up by point_index")
        U = up[["x_m", "y_m", "z_m"]].to_numpy()
        L = lo[["x_m", "y_m", "z_m"]].to_numpy()
        ligs.append(Ligament(name=name, kind=name.split("_")[0], upper=U, lower=L, extra_length=np.zeros(len(U))))
    for side in ("left", "right"):
        s = sub[sub["side"] == side]
        sp = s[s["structure"] == "facet_superior"].sort_values("point_index")[["x_m", "y_m", "z_m"]].to_numpy()
        ip = s[s["structure"] == "facet_inferior"].sort_values("point_index")[["x_m", "y_m", "z_m"]].to_numpy()
        if len(sp) or len(ip):
            if sp.shape != (9, 3) or ip.shape != (9, 3):
                raise GeometryError(f"landmarks {level} facet {side}: expected 9 superior and 9 inferior points, "
                                    f"got {len(sp)} and {len(ip)}")
            facets[side] = FacetLandmarks(superior=sp, inferior=ip)
    return ligs, facets


def default_csv_path() -> Path:
    return resources.data_dir() / "landmarks" / "myo_sim_landmarks.csv"


def main():  # pragma: no cover
    from . import myo_sim  # noqa: PLC0415
    meshes = myo_sim.load_raw_meshes()
    df = propose_landmarks(meshes, version=myo_sim.package_version())
    out = default_csv_path()
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out, index=False, float_format="%.6f")
    print(f"wrote {len(df)} rows to {out}")


if __name__ == "__main__":  # pragma: no cover
    main()
