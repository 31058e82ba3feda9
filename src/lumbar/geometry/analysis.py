"""Geometric helpers shared by the loaders: plane fits, endplates, disc measures, centroids."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    import trimesh

EZ = np.array([0.0, 0.0, 1.0])


def plane_fit(points: np.ndarray, up=EZ):
    """Least-squares plane: (centroid, unit normal = smallest-variance axis, oriented along ``up``)."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    n = vt[-1]
    if n @ up < 0:
        n = -n
    return c, n / np.linalg.norm(n)


def sagittal_split(mesh: trimesh.Trimesh, y_mid: float = 0.0):
    """x of the posterior wall of the vertebral body and of the anterior edge of the lamina at the midline.

    Mid-sagittal section (plane y = y_mid): the anterior-most closed polygon is the vertebral body, the
    next one posteriorly the lamina/spinous process; the canal lies between them.
    """
    sec = mesh.section(plane_normal=[0, 1, 0], plane_origin=[0, y_mid, 0])
    if sec is None:
        return None, None
    p2, T = sec.to_2D()
    import trimesh  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    boxes = []
    for poly in p2.polygons_full:
        b = np.array(poly.exterior.coords)
        b3 = trimesh.transform_points(np.c_[b, np.zeros(len(b))], T)
        boxes.append((b3[:, 0].min(), b3[:, 0].max()))
    boxes.sort(key=lambda t: -t[1])
    if len(boxes) < 2:
        return None, None
    return boxes[0][0], boxes[1][1]


def hull_centroid(points: np.ndarray) -> np.ndarray:
    import trimesh  # noqa: PLC0415
    return np.asarray(trimesh.convex.convex_hull(points).center_mass, dtype=float)


def volume_centroid(mesh: trimesh.Trimesh) -> np.ndarray:
    """Volume centroid if watertight, else that of the convex hull (documented approximation)."""
    if mesh.is_watertight and mesh.volume > 0:
        return np.asarray(mesh.center_mass, dtype=float)
    return hull_centroid(mesh.vertices)


def inferior_endplate(mesh: trimesh.Trimesh, face_mask: np.ndarray, band: float = 0.005):
    """Inferior endplate of a vertebral body from its downward-facing faces.

    Faces in ``face_mask`` (the body part) whose outward normal points inferiorly (n.z < -0.5) and whose
    centres lie within ``band`` of the body's lowest point.  Returns (area-weighted centroid, unit normal
    pointing superior = minus the area-weighted mean outward normal, face indices).
    """
    fc, fn, fa = mesh.triangles_center, mesh.face_normals, mesh.area_faces
    zmin = fc[face_mask, 2].min()
    sel = face_mask & (fn[:, 2] < -0.5) & (fc[:, 2] < zmin + band)
    if sel.sum() < 1:
        sel = face_mask & (fc[:, 2] < zmin + band)
    w = fa[sel]
    c = (fc[sel] * w[:, None]).sum(0) / w.sum()
    n = -(fn[sel] * w[:, None]).sum(0)
    n /= np.linalg.norm(n)
    return c, n, np.where(sel)[0]


def facing_endplate(mesh: trimesh.Trimesh, c_up: np.ndarray, n_up: np.ndarray, radius: float,
                    band: float = 0.005):
    """Superior endplate of the lower vertebra, found from the upper one's inferior endplate (c_up, n_up):
    faces of ``mesh`` whose outward normal faces the upper endplate (n.n_up > 0.5), whose centres lie
    below c_up inside the cylinder of the given radius about the axis (c_up, n_up), and within ``band``
    of the highest such face along n_up.  Returns (area-weighted centroid, unit normal, face indices)."""
    fc, fn, fa = mesh.triangles_center, mesh.face_normals, mesh.area_faces
    d = fc - c_up
    h = d @ n_up
    r = np.linalg.norm(d - np.outer(h, n_up), axis=1)
    cand = (r < radius) & (h < 0) & (fn @ n_up > 0.5)
    if not cand.any():
        raise ValueError("no superior endplate faces found below the upper vertebra")
    sel = cand & (h > h[cand].max() - band)
    w = fa[sel]
    c = (fc[sel] * w[:, None]).sum(0) / w.sum()
    n = (fn[sel] * w[:, None]).sum(0)
    n /= np.linalg.norm(n)
    return c, n, np.where(sel)[0]


def section_area(mesh: trimesh.Trimesh, origin, normal, inside_point=None) -> float:
    """Area of the section polygon of ``mesh`` by the plane (origin, normal) that contains (or lies
    nearest to) ``inside_point``; sum over polygon.area of that polygon only."""
    sec = mesh.section(plane_normal=normal, plane_origin=origin)
    if sec is None:
        return float("nan")
    p2, T = sec.to_2D()
    polys = list(p2.polygons_full)
    if not polys:
        return float("nan")
    if inside_point is None:
        return float(sum(p.area for p in polys))
    import shapely.geometry as sg  # noqa: PLC0415
    import trimesh  # noqa: PLC0415
    q = trimesh.transform_points(np.atleast_2d(inside_point), np.linalg.inv(T))[0, :2]
    pt = sg.Point(q)
    best = min(polys, key=lambda p: p.distance(pt))
    return float(best.area)


def projected_area(points: np.ndarray, normal: np.ndarray) -> float:
    """Convex-hull area of ``points`` projected on the plane with the given normal."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    q = np.c_[points @ a, points @ b]
    from scipy.spatial import ConvexHull  # noqa: PLC0415
    return float(ConvexHull(q).volume)


def facet_sagittal_angle_deg(facet) -> float:
    """Orientation of a facet joint in the transverse plane [deg]: the angle between the joint plane and the
    sagittal plane (0 = sagittal facets, 90 = coronal facets), from the joint normal = the least-variance axis of
    all its landmarks (the w axis of the paper's Eq. 4 surface fit, ``lumbar.mechanics.elements.facet``)."""
    P = np.vstack([np.asarray(facet.superior, float), np.asarray(facet.inferior, float)])
    w = np.linalg.svd(P - P.mean(0))[2][2]
    return float(np.degrees(np.arctan2(abs(w[0]), abs(w[1]))))


def summary_table(geo) -> pd.DataFrame:
    """One row per level: disc centre/normal/CSA/height, facet landmarks and orientation
    (:func:`facet_sagittal_angle_deg`), ligament fibres (mm)."""

    rows = []
    for name in sorted(geo.levels):
        lev = geo.levels[name]
        row = {"geometry": geo.name, "level": name, "upper": lev.upper, "lower": lev.lower}
        for ax, c in zip("xyz", lev.disc_centre):
            row[f"disc_centre_{ax}_mm"] = 1e3 * float(c)
        for ax, n in zip("xyz", lev.disc_normal):
            row[f"disc_normal_{ax}"] = float(n)
        row["disc_csa_mm2"] = 1e6 * float(lev.disc_csa)
        row["disc_height_mm"] = 1e3 * float(lev.disc_height)
        row["facet_landmarks_n"] = int(sum(len(f.superior) + len(f.inferior) for f in lev.facets.values()))
        for side in sorted(lev.facets):
            row[f"facet_{side}_sagittal_angle_deg"] = facet_sagittal_angle_deg(lev.facets[side])
        for lig in lev.ligaments:
            length = np.linalg.norm(np.asarray(lig.upper) - np.asarray(lig.lower), axis=1) + np.asarray(lig.extra_length)
            row[f"{lig.name}_n_fibres"] = int(len(length))
            row[f"{lig.name}_mean_length_mm"] = 1e3 * float(length.mean()) if len(length) else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ closest points on a surface
_CLOSEST_CACHE = "lumbar_closest_point_trees"
#: the triangles are searched in groups of similar circumradius (from their centre), split at these quantiles: each
#: group's KD-tree of centres is searched with its own largest radius as margin (a hole's fan or a sliver would
#: otherwise widen every search)
_RADIUS_QUANTILES = (0.9, 0.99)


def _closest_trees(mesh):
    from scipy.spatial import cKDTree  # noqa: PLC0415 - scipy.spatial where geometry is computed
    if _CLOSEST_CACHE in mesh._cache:      # trimesh's cache: cleared when the mesh's data change
        return mesh._cache[_CLOSEST_CACHE]
    tri = np.asarray(mesh.triangles)
    centre = tri.mean(axis=1)
    radius = np.linalg.norm(tri - centre[:, None, :], axis=2).max(axis=1)
    edges = np.r_[-np.inf, np.quantile(radius, _RADIUS_QUANTILES), np.inf]
    groups = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        idx = np.flatnonzero((radius > lo) & (radius <= hi))
        if len(idx):
            groups.append((cKDTree(centre[idx]), idx, float(radius[idx].max())))
    out = (groups, tri)
    mesh._cache[_CLOSEST_CACHE] = out
    return out


def _nearest_of(Q, qi, fi, tri):
    """Per query point (index qi into Q) the candidate triangle fi with the closest point: (points, distances,
    triangles, which rows of Q got one)."""
    from trimesh.triangles import closest_point as on_triangles  # noqa: PLC0415 - the exact point-triangle step
    cp = on_triangles(tri[fi], Q[qi])
    d = np.linalg.norm(cp - Q[qi], axis=1)
    order = np.lexsort((fi, d, qi))            # per point the smallest distance, then the lowest triangle index
    first = order[np.r_[True, qi[order][1:] != qi[order][:-1]]]
    return cp[first], d[first], fi[first], qi[first]


def closest_point(mesh, points, chunk: int = 4096):
    """(closest points on the surface of ``mesh``, their distances, their triangles) of ``points`` (n, 3), as
    ``trimesh.proximity.closest_point`` returns them, exactly (trimesh's candidate search missed the closest
    triangle for some points, up to 0.03 mm off on a Visible Human vertebra) and without its R-tree of triangle
    boxes, whose construction took 0.45 s per 40,000 triangles and was repeated for every moved copy of a mesh. Two
    passes over KD-trees of the triangle centres (grouped by circumradius): the exact closest points on the
    triangles of the 8 nearest centres bound each point's distance by d; every triangle holding a point within d
    has its centre within d + its circumradius, so the second pass takes, per group, the triangles whose centres lie
    within d + the group's largest circumradius. The trees are cached on the mesh (trimesh clears its cache when
    the mesh changes)."""
    P = np.atleast_2d(np.asarray(points, float))
    groups, tri = _closest_trees(mesh)
    best_p = np.empty_like(P)
    best_d = np.full(len(P), np.inf)
    best_f = np.zeros(len(P), np.int64)
    for s in range(0, len(P), chunk):
        Q = P[s:s + chunk]
        n = len(Q)
        qi, fi = [], []
        for tree, idx, _ in groups:
            k = min(8, len(idx))
            j = np.asarray(tree.query(Q, k=k)[1]).reshape(n, -1)
            qi.append(np.repeat(np.arange(n), j.shape[1]))
            fi.append(idx[j.ravel()])
        _, d1, _, _ = _nearest_of(Q, np.concatenate(qi), np.concatenate(fi), tri)
        qi, fi = [], []
        for tree, idx, rmax in groups:
            hits = tree.query_ball_point(Q, d1 + rmax + 1e-12, return_sorted=False)
            counts = np.fromiter((len(h) for h in hits), np.int64, n)
            if counts.sum():
                qi.append(np.repeat(np.arange(n), counts))
                fi.append(idx[np.concatenate(hits).astype(np.int64)])
        cp, d, f, q = _nearest_of(Q, np.concatenate(qi), np.concatenate(fi), tri)
        best_p[s + q], best_d[s + q], best_f[s + q] = cp, d, f
    return best_p, best_d, best_f
