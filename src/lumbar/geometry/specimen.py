"""A user's own specimen: the project frame found from the anatomy, and the disc measures from the endplates.

Input: ``{vertebra token ("L1".."L5", "S1"): trimesh.Trimesh}`` in metres, in the input's own axes, and the declared
axes of those coordinates: a three-letter code (``"LPS"`` 3D Slicer / DICOM patient coordinates, ``"RAS"`` NIfTI
world, ``"project"`` = ``"ALS"``: x anterior, y left, z superior), or ``"any"`` (no declaration: the orientation is
taken from the anatomy alone). :func:`align_to_project` returns the 4x4 rigid transform input -> project frame and
what it detected; the rules are in docs/specimen.md:

* superior: the column's direction, from the lowest to the highest vertebral body of the vertebrae present
  (the level tokens order them); one vertebra alone takes the declared superior axis;
* mid-sagittal plane: per vertebra the plane of best mirror symmetry of its surface (iterated reflection ICP from
  the two principal axes across the column; the better of the two), the left-right axis is their mean normal;
* anterior: per vertebra, the end of its antero-posterior extent whose 12 mm end slab is wider left-right (the
  vertebral body; the other end is the spinous process), the majority over the vertebrae;
* left = superior x anterior (a right-handed frame; the input coordinates are right-handed when the declared code
  is, and a mirrored mesh turns its faces inwards: negative enclosed volume);
* origin: the mean of the vertebral-body centroids, moved onto the mid-sagittal plane.

Errors (:class:`GeometryError`, naming the mesh and what was detected): a left-handed declared code, a mesh whose
faces wind inwards (mirrored), the anatomy's anterior opposite the declared anterior (anterior/posterior swapped),
the anatomy's superior opposite the declared superior (declared axes contradicting the anatomy).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import analysis as A
from .core import GeometryError, VERTEBRA_NAMES
from .register import mesh_sample, welded

MM = 1e-3
#: project directions of the letters of an axes code (x anterior, y left, z superior)
LETTERS = {"A": (0, 1.0), "P": (0, -1.0), "L": (1, 1.0), "R": (1, -1.0), "S": (2, 1.0), "I": (2, -1.0)}
AXES_ALIASES = {"project": "ALS"}
END_SLAB_M = 0.012          # anterior rule: width of the end slabs compared
MAX_SAMPLES = 3000          # vertices per vertebra used by the frame rules (register.mesh_sample)
SYMMETRY_ITERATIONS = 25
ENDPLATE_BAND_M = 0.005
ENDPLATE_RADIUS_M = 0.012
CSA_OFFSET_M = 0.002
#: is it a vertebra (:func:`check_vertebra_shape`; design limits, far from both sides): the volume over its convex
#: hull's (0.38-0.50 for the Visible Human L1-S1, the morphable mean L2-L5 and TotalSegmentator's example meshed
#: here; 1 for an ellipsoid or any convex blob) and, per lumbar vertebra, the end slab of the vertebral body against
#: that of the spinous process (the anterior rule's widths: 3.4-6.6 times on the same sets; about 1 for an
#: ellipsoid, which has no posterior arch or processes)
MAX_SOLIDITY = 0.75
MIN_BODY_TO_PROCESS_WIDTH = 1.5


def declared_matrix(axes: str, where: str = "") -> np.ndarray | None:
    """3x3 matrix D whose column i is the project direction of the input's +axis i (``None`` for ``"any"``).

    A code names, per input axis, the anatomical direction it points to (L/R, A/P, S/I), e.g. ``"LPS"``: +x left,
    +y posterior, +z superior. Raises :class:`GeometryError` for an unknown or left-handed code (a left-handed code
    would mirror the specimen)."""
    if axes is None or str(axes).lower() == "any":
        return None
    code = AXES_ALIASES.get(str(axes).lower(), str(axes).upper())
    if len(code) != 3 or any(c not in LETTERS for c in code) or len({LETTERS[c][0] for c in code}) != 3:
        raise GeometryError(f"{where}declared axes {axes!r}: expected a three-letter code with one of L/R, A/P, S/I "
                            "each (e.g. 'LPS' for 3D Slicer/DICOM, 'RAS' for NIfTI world), 'project' or 'any'")
    D = np.zeros((3, 3))
    for i, c in enumerate(code):
        row, sign = LETTERS[c]
        D[row, i] = sign
    if np.linalg.det(D) < 0:
        raise GeometryError(f"{where}declared axes {axes!r} are left-handed (determinant -1): mapping them to the "
                            "project frame would mirror the specimen (left and right exchanged); expected a "
                            "right-handed code such as 'LPS' or 'RAS'")
    return D


def check_winding(mesh, name: str, source: str = "") -> float:
    """Signed enclosed volume [m^3] of ``mesh``; raises if negative (faces wound inwards: a mirrored mesh)."""
    vol = float(mesh.volume)
    if not np.isfinite(vol) or vol <= 0:
        where = f"{name} mesh{f' ({source})' if source else ''}"
        raise GeometryError(f"{where}: enclosed volume {vol * 1e6:.4g} cm^3 is not positive: its faces wind inwards, "
                            "as after a mirroring (one axis flipped on export without re-ordering the faces); "
                            "expected outward-wound faces of an unmirrored surface")
    return vol


def solidity(mesh) -> float:
    """Enclosed volume over the volume of the convex hull of ``mesh`` (a vertebra with its arch and processes is
    far from convex)."""
    hull = float(mesh.convex_hull.volume)
    return float(mesh.volume) / hull if hull > 0 else float("nan")


def check_vertebra_shape(name: str, mesh, widths=None, source: str = "") -> dict:
    """Refuse a surface that is not a vertebra (:class:`GeometryError` naming it): a vertebra with its posterior
    arch and processes fills less than ``MAX_SOLIDITY`` of its convex hull, and (lumbar, ``widths`` = [body end,
    process end] end-slab widths of the anterior rule) its body end is at least ``MIN_BODY_TO_PROCESS_WIDTH`` times
    as wide as its process end. Returns the measures (transform.json)."""
    where = f"{name} mesh{f' ({source})' if source else ''}"
    sol = solidity(mesh)
    out = {"solidity": round(sol, 3)}
    if not sol <= MAX_SOLIDITY:
        raise GeometryError(f"{where}: fills {sol:.0%} of its convex hull; expected a vertebra (body, arch and "
                            f"processes fill 38-50 % of theirs; at most {MAX_SOLIDITY:.0%} accepted): a convex shape "
                            "(an ellipsoid, a vertebral body alone, a filled or wrapped surface) is not a vertebra")
    if widths is not None:
        body, proc = (float(w) for w in widths)
        ratio = body / proc if proc > 0 else np.inf
        out["body_to_process_width"] = round(ratio, 2)
        if not ratio >= MIN_BODY_TO_PROCESS_WIDTH:
            raise GeometryError(f"{where}: its two ends across the column are {body * 1e3:.1f} and {proc * 1e3:.1f} mm "
                                f"wide (12 mm end slabs); expected a vertebral body at one end at least "
                                f"{MIN_BODY_TO_PROCESS_WIDTH:g} times as wide as the spinous process at the other "
                                "(3.4-6.6 times on the shipped and the example CT vertebrae): no posterior arch and "
                                "processes")
    return out


def _samples(mesh) -> np.ndarray:
    return mesh_sample(welded(mesh), MAX_SAMPLES)[0]


def symmetry_plane(points: np.ndarray, normal0: np.ndarray, iterations: int = SYMMETRY_ITERATIONS):
    """Plane of best mirror symmetry of ``points`` from the start normal ``normal0`` (through their centroid).

    Iterated reflection ICP: reflect, pair each point with the nearest original point of its mirror image, the new
    normal is the principal direction of the pair differences and the plane passes through the pairs' midpoints.
    Returns (normal (unit), offset d: plane n.x = d, rms pair distance [m])."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    tree = cKDTree(points)
    n = np.asarray(normal0, float) / np.linalg.norm(normal0)
    d = float(points.mean(0) @ n)
    rms = np.inf
    for _ in range(iterations):
        refl = points - 2.0 * ((points @ n) - d)[:, None] * n
        dist, j = tree.query(refl)
        keep = dist <= np.quantile(dist, 0.9)
        diff = (points - points[j])[keep]
        diff = diff[np.linalg.norm(diff, axis=1) > 1e-9]
        if len(diff) < 10:
            break
        M = diff.T @ diff
        w, V = np.linalg.eigh(M)
        n_new = V[:, -1] * np.sign(V[:, -1] @ n or 1.0)
        mid = 0.5 * (points + points[j])[keep]
        n_new = n_new / np.linalg.norm(n_new)
        d_new = float(np.median(mid @ n_new))
        rms = float(np.sqrt(np.mean(dist[keep] ** 2)))
        done = bool(np.array_equal(n_new, n) and d_new == d)   # a fixed point: every further step repeats it
        n, d = n_new, d_new
        if done:
            break
    return n, d, rms


def _perp(v, axis):
    v = v - (v @ axis) * axis
    return v / np.linalg.norm(v)


def _anterior_sign(points, a, n):
    """+1 if +a points to the vertebral body (the wider end slab across ``n``), else -1; and the two widths [m]."""
    t = points @ a
    w = points @ n
    lo, hi = t.min(), t.max()
    wid = []
    for sel in (t > hi - END_SLAB_M, t < lo + END_SLAB_M):
        q = w[sel]
        wid.append(float(np.quantile(q, 0.95) - np.quantile(q, 0.05)) if len(q) > 4 else 0.0)
    return (1.0 if wid[0] >= wid[1] else -1.0), wid


@dataclass
class Alignment:
    """Input -> project frame: ``transform`` (4x4, rigid, det +1) and what the rules detected."""
    transform: np.ndarray
    axes: str
    detected: dict = field(default_factory=dict)

    def apply(self, points) -> np.ndarray:
        P = np.atleast_2d(np.asarray(points, float))
        return P @ self.transform[:3, :3].T + self.transform[:3, 3]

    def inverse(self, points) -> np.ndarray:
        P = np.atleast_2d(np.asarray(points, float)) - self.transform[:3, 3]
        return P @ self.transform[:3, :3]


def _order(meshes: dict) -> list[str]:
    bad = [k for k in meshes if k not in VERTEBRA_NAMES]
    if bad:
        raise GeometryError(f"unknown vertebra token(s) {bad}; expected some of {list(VERTEBRA_NAMES)}")
    return [v for v in VERTEBRA_NAMES if v in meshes]


def _superior(names, pts, D, sources):
    """Column superior direction (input axes) from the ordered vertebrae, or the declared one for a single vertebra."""
    lumbar = [v for v in names if v != "S1"]
    if len(names) >= 2:
        cen = {v: pts[v].mean(0) for v in names}
        use = lumbar if len(lumbar) >= 2 else names
        s = sum(cen[a] - cen[b] for a, b in zip(use[:-1], use[1:]))
        return s / np.linalg.norm(s), "column: lowest to highest vertebra present"
    if D is None:
        raise GeometryError(f"{sources.get(names[0], names[0])}: one vertebra alone and axes 'any': the superior "
                            "direction cannot be told from one vertebra; declare the axes (e.g. --axes LPS)")
    return D.T @ np.array([0.0, 0.0, 1.0]), "declared axes (one vertebra)"


def align_to_project(meshes: dict, axes: str = "LPS", sources: dict | None = None, turned=()) -> Alignment:
    """Rigid transform of a specimen (``{token: Trimesh}`` in metres, input axes) to the project frame (module doc).

    ``turned``: the vertebrae whose surfaces were wound inside-out and turned outwards by the reader
    (:func:`lumbar.geometry.specimen_io.close_surface`): each lumbar one must have its own vertebral body towards the
    anterior found for the specimen (and, with declared axes, the declared anterior), else its file is mirrored
    (about an axis other than the left-right one) and refused. Every vertebra must have a vertebra's shape
    (:func:`check_vertebra_shape`)."""
    sources = dict(sources or {})
    turned = [v for v in turned if v in meshes]
    names = _order(meshes)
    if not names:
        raise GeometryError("no vertebra meshes given; expected some of L1-L5, S1")
    D = declared_matrix(axes, where="")
    for v in names:
        check_winding(meshes[v], v, sources.get(v, ""))
    pts = {v: _samples(meshes[v]) for v in names}
    s, s_rule = _superior(names, pts, D, sources)
    lumbar = [v for v in names if v != "S1"] or names
    normals, offsets, signs, widths, rms = {}, {}, {}, {}, {}
    for v in lumbar:
        P = pts[v]
        Q = P - P.mean(0)
        Q = Q - np.outer(Q @ s, s)
        _, _, vt = np.linalg.svd(Q, full_matrices=False)
        # start normals every 30 deg across the column from the first principal axis (the principal axes of a
        # vertebra as wide as it is deep, e.g. L5, lie diagonally); the best after a few steps is refined
        e1, e2 = _perp(vt[0], s), np.cross(s, _perp(vt[0], s))
        starts = [np.cos(t) * e1 + np.sin(t) * e2 for t in np.radians(np.arange(0, 180, 30))]
        trial = [symmetry_plane(P, c, iterations=6) for c in starts]
        n0 = trial[int(np.argmin([t[2] for t in trial]))][0]
        n, d, r = symmetry_plane(P, n0)
        m = P.mean(0)
        p0 = m - (m @ n - d) * n            # a point of the plane (translation-equivariant, unlike d)
        n = _perp(n, s)
        a = np.cross(n, s)
        sg, wid = _anterior_sign(P, a, n)
        # widths: [the vertebra's own body end, its process end]
        normals[v], offsets[v], signs[v], widths[v], rms[v] = n, p0, sg * a, wid if sg > 0 else wid[::-1], r
    # one left-right axis: the mean of the per-vertebra symmetry normals (signs made consistent)
    shape = {}
    for v in names:
        try:
            shape[v] = check_vertebra_shape(v, meshes[v], widths.get(v) if v != "S1" else None, sources.get(v, ""))
        except GeometryError as exc:
            if v not in turned:
                raise
            raise GeometryError(f"{exc}; its surface was wound inside-out: a file mirrored about a plane across "
                                "the vertebra?") from None
    ref = normals[lumbar[0]]
    nbar = sum(normals[v] * np.sign(normals[v] @ ref) for v in lumbar)
    nbar = _perp(nbar, s)
    votes = [np.sign(signs[v] @ np.cross(nbar, s)) for v in lumbar]
    x = np.cross(nbar, s)
    # the majority of the vertebrae decides; a tie (two vertebrae disagreeing) by the declared anterior, if any
    tie = 1.0 if D is None or float((D @ x)[0]) >= 0 else -1.0
    x = x * (1.0 if sum(votes) > 0 else -1.0 if sum(votes) < 0 else tie)
    # an inside-out file whose own body lies against the specimen's anterior: that file alone mirrored
    against = [v for v in turned if v in signs and float(signs[v] @ x) < 0]
    if against:
        what = ", ".join(f"{v}: {sources.get(v) or 'mesh'}" for v in against)
        raise GeometryError(f"{what}: the surface was wound inside-out and its vertebral body lies towards the "
                            "spinous processes of the other vertebrae: a mirrored file (an axis other than "
                            "left-right flipped); expected unmirrored coordinates")
    z = s
    y = np.cross(z, x)
    R = np.vstack([x, y, z])
    # origin: the mean of the body centroids, each moved onto its vertebra's symmetry plane
    cents = [_body_centroid_input(pts[v], x) for v in lumbar]
    o = np.mean([c - ((c - offsets[v]) @ normals[v]) * normals[v] for c, v in zip(cents, lumbar)], axis=0)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ o
    detected = dict(superior_rule=s_rule, superior_input=s.tolist(), anterior_input=x.tolist(), left_input=y.tolist(),
                    anterior_votes={v: int(np.sign(signs[v] @ x)) for v in lumbar},
                    end_slab_widths_mm={v: [round(w * 1e3, 2) for w in widths[v]] for v in lumbar},
                    symmetry_rms_mm={v: round(rms[v] * 1e3, 3) for v in lumbar}, shape=shape,
                    inside_out_turned=list(turned))
    if D is not None:
        ant, sup = float((D @ x)[0]), float((D @ s)[2])
        ang = float(np.degrees(np.arccos(np.clip((np.trace(R @ D.T) - 1) / 2, -1, 1))))
        detected.update(declared_axes=axes, angle_to_declared_deg=round(ang, 2),
                        anterior_dot_declared=round(ant, 4), superior_dot_declared=round(sup, 4))
        what = ", ".join(f"{v}: {sources.get(v) or 'mesh'}" for v in names)
        mirror = (f"; the surfaces of {', '.join(turned)} were wound inside-out, the signature of a mirrored export "
                  "(one axis flipped without re-ordering the faces)" if turned else "")
        if ant < 0:
            raise GeometryError(f"{what}: anterior/posterior swapped relative to the declared axes {axes!r}: the "
                                f"vertebral bodies lie towards the declared posterior (anterior . declared anterior = "
                                f"{ant:.2f}; end-slab widths body/process {detected['end_slab_widths_mm']} mm){mirror}; "
                                "check the axes code (LPS for Slicer/DICOM, RAS for NIfTI world)"
                                + (" and export without mirroring" if turned else ""))
        if sup < 0:
            raise GeometryError(f"{what}: the declared axes {axes!r} contradict the anatomy: the column runs "
                                f"{s_rule} towards the declared inferior (superior . declared superior = {sup:.2f})"
                                f"{mirror}; check the axes code and the vertebra names of the files")
    return Alignment(transform=T, axes=str(axes), detected=detected)


def _body_centroid_input(P, x):
    """Centroid of the anterior 40 % (along ``x``) of a vertebra's points: its vertebral body."""
    t = P @ x
    return P[t > np.quantile(t, 0.6)].mean(0)


# ---------------------------------------------------------------------------------------------------------------
# per vertebra and per level, in the project frame
# ---------------------------------------------------------------------------------------------------------------

def body_split(mesh):
    """(x of the vertebral body's posterior wall, x of the lamina's anterior edge) at the mid-sagittal plane of the
    vertebra (project frame; :func:`lumbar.geometry.analysis.sagittal_split` through the vertebra's own mid-plane
    y = median y of its vertices); the body = points anterior of the wall."""
    y0 = float(np.median(np.asarray(mesh.vertices)[:, 1]))
    xp, xl = A.sagittal_split(mesh, y_mid=y0)
    if xp is None:
        v = np.asarray(mesh.vertices)
        xp = float(np.quantile(v[:, 0], 0.55))
        xl = float(np.quantile(v[:, 0], 0.4))
    return xp, xl


def _inferior_endplate(mesh, body_faces, direction):
    """Inferior endplate of the body faces: outward normals facing -``direction`` within ``ENDPLATE_BAND_M`` of the
    body's lowest point along it; two passes, the second along the first pass's own normal. Returns (area-weighted
    centre, unit normal pointing superior)."""
    fc, fn, fa = mesh.triangles_center, mesh.face_normals, mesh.area_faces
    d = np.asarray(direction, float)
    for _ in range(2):
        down = body_faces & (fn @ d < -0.5)
        if not down.any():
            raise GeometryError("no downward-facing faces on the vertebral body (inferior endplate not found)")
        h = fc @ d
        sel = down & (h < h[down].min() + ENDPLATE_BAND_M)
        w = fa[sel]
        c = (fc[sel] * w[:, None]).sum(0) / w.sum()
        n = -(fn[sel] * w[:, None]).sum(0)
        d = n / np.linalg.norm(n)
    return c, d


def body_centroid(mesh, x_post: float) -> np.ndarray:
    """Reference point c_b of a lumbar vertebra: volume centroid of the convex hull of its vertices anterior of the
    posterior wall of the body (as the myo-sim loader, lumbar.geometry.loader)."""
    v = np.asarray(mesh.vertices)
    return A.hull_centroid(v[v[:, 0] > x_post])


def sacrum_centroid(mesh, endplate_centre, endplate_normal) -> np.ndarray:
    """Reference point of the sacrum: hull centroid of its vertices within 25 mm below the S1 endplate and 20 mm of
    its axis (as the myo-sim loader)."""
    d = np.asarray(mesh.vertices) - endplate_centre
    h = d @ endplate_normal
    r = np.linalg.norm(d - np.outer(h, endplate_normal), axis=1)
    sel = (h < 0.5e-3) & (h > -0.025) & (r < 0.02)
    if sel.sum() < 4:
        raise GeometryError("S1: fewer than 4 vertices within 25 mm below the S1 endplate; cannot place its centroid")
    return A.hull_centroid(np.asarray(mesh.vertices)[sel])


def disc_from_endplates(upper_mesh, lower_mesh, upper_centroid, lower_centroid, x_post_upper):
    """Disc of one level from the endplates facing it (project frame): the upper vertebra's inferior endplate
    (:func:`_inferior_endplate`, starting along the line between the two body centroids) and the lower vertebra's
    facing superior endplate (:func:`lumbar.geometry.analysis.facing_endplate`, 12 mm radius). centre = midpoint of
    the two endplate centres, normal = their normals' mean, height = their distance along it, cross-section = the
    upper body's section 2 mm above its inferior endplate. Returns dict(centre, normal, height, csa, inferior
    (centre, normal), superior (centre, normal))."""
    d0 = np.asarray(upper_centroid, float) - np.asarray(lower_centroid, float)
    d0 /= np.linalg.norm(d0)
    body = upper_mesh.triangles_center[:, 0] > x_post_upper
    c_inf, n_inf = _inferior_endplate(upper_mesh, body, d0)
    try:
        c_sup, n_sup, _ = A.facing_endplate(lower_mesh, c_inf, n_inf, radius=ENDPLATE_RADIUS_M)
    except ValueError as exc:
        raise GeometryError(f"superior endplate of the lower vertebra not found below the upper one: {exc}") from None
    n = n_inf + n_sup
    n /= np.linalg.norm(n)
    origin = c_inf + CSA_OFFSET_M * n_inf
    csa = A.section_area(upper_mesh, origin, n_inf, inside_point=origin)
    return dict(centre=0.5 * (c_inf + c_sup), normal=n, height=float((c_inf - c_sup) @ n), csa=float(csa),
                inferior=(c_inf, n_inf), superior=(c_sup, n_sup))


def level_disc(upper_mesh, lower_mesh, lower_is_sacrum: bool = False) -> dict:
    """:func:`disc_from_endplates` of one level from its two meshes alone (project frame), with the reference points
    of ``lumbar.geometry.specimen_build.centroids_of``: the body centroids, the sacrum's from its endplate below the
    upper vertebra."""
    x_post = body_split(upper_mesh)[0]
    c_u = body_centroid(upper_mesh, x_post)
    if lower_is_sacrum:
        d = disc_from_endplates(upper_mesh, lower_mesh, c_u, np.asarray(lower_mesh.vertices).mean(0), x_post)
        c_l = sacrum_centroid(lower_mesh, *d["superior"])
    else:
        c_l = body_centroid(lower_mesh, body_split(lower_mesh)[0])
    return disc_from_endplates(upper_mesh, lower_mesh, c_u, c_l, x_post)
