"""Plausibility checks of loaded vertebra meshes (units, closedness, frame), run by ``load_geometry``.

A mesh that fails raises :class:`GeometryError` naming the vertebra, its source file and what was expected:

* size: a lumbar vertebra or the sacrum spans ``MIN_EXTENT_M``..``MAX_EXTENT_M`` (metres); millimetres are
  caught on reading (``meshio.MAX_EXTENT_M``), a mesh scaled down by 1000 (or given in km) here;
* closed enough for a cross-section: the plane z = const through the vertebral-body centroid cuts the
  mesh in at least one closed loop enclosing ``MIN_SECTION_M2`` (the disc CSA and the IDP need it);
* frame (x anterior, y left, z superior): the vertebral body lies anterior (+x) of the centre of the
  bounding box (the posterior elements point to -x), and the vertebrae are stacked along +z from S1 up;
* insertions: every ligament fibre end and facet landmark lies within ``INSERTION_TOL_M`` of the surface
  of the vertebra it is fixed to (via-point fibres end at the disc surface, up to half a disc height away).
"""
from __future__ import annotations

import numpy as np

from .core import GeometryError

MIN_EXTENT_M = 0.02       # largest extent of a lumbar vertebra is 5-10 cm; 2 cm is far below any adult
MAX_EXTENT_M = 0.3
MIN_SECTION_M2 = 2e-4     # 2 cm^2; an adult lumbar vertebral body has 10-20 cm^2
ORDER = ("S1", "L5", "L4", "L3", "L2", "L1")
INSERTION_TOL_M = 0.010   # 10 mm: via-point ALL/PLL ends of the Visible Human sit up to ~8 mm off the bone


def _surface_distance(mesh, pts, trees=None):
    """Distance of each point to the mesh surface; ``trees`` (dict) keeps one vertex KD-tree per dense mesh across
    calls (a check of one geometry queries every vertebra some 20 times)."""
    pts = np.asarray(pts, float).reshape(-1, 3)
    if len(mesh.vertices) > 5000:          # dense mesh: the nearest vertex is within a fraction of a mm
        from scipy.spatial import cKDTree  # noqa: PLC0415
        tree = None if trees is None else trees.get(id(mesh))
        if tree is None:
            tree = cKDTree(mesh.vertices)
            if trees is not None:
                trees[id(mesh)] = tree
        return tree.query(pts)[0]
    import trimesh  # noqa: PLC0415
    return trimesh.proximity.closest_point(mesh, pts)[1]


def check_insertions(geo) -> None:
    """Ligament fibre ends and facet landmarks on (or near) the vertebra they are fixed to."""
    trees = {}
    for lname, lev in geo.levels.items():
        groups = [(f"ligament {lig.name}", end, body, pts) for lig in lev.ligaments
                  for end, body, pts in (("upper", lev.upper, lig.upper), ("lower", lev.lower, lig.lower))]
        groups += [(f"facet {side}", end, body, pts) for side, f in lev.facets.items()
                   for end, body, pts in (("superior", lev.lower, f.superior), ("inferior", lev.upper, f.inferior))]
        for what, end, body, pts in groups:
            if body not in geo.vertebrae or len(pts) == 0:
                continue
            d = _surface_distance(geo.vertebrae[body].mesh, pts, trees)
            if np.max(d) > INSERTION_TOL_M:
                j = int(np.argmax(d))
                raise GeometryError(f"{lname} {what}: point {j} ({end} end, on {body}) is {d[j] * 1e3:.1f} mm from "
                                    f"the {body} mesh surface; expected within {INSERTION_TOL_M * 1e3:.0f} mm "
                                    "(metres, project frame)")


def _closed_loop_areas(mesh, origin) -> list[float]:
    sec = mesh.section(plane_origin=np.asarray(origin, float), plane_normal=[0.0, 0.0, 1.0])
    if sec is None:
        return []
    areas = []
    for loop in sec.discrete:
        loop = np.asarray(loop)
        if len(loop) >= 4 and np.linalg.norm(loop[0] - loop[-1]) < 1e-6:
            x, y = loop[:, 0], loop[:, 1]
            areas.append(0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))))
    return areas


def check_vertebra(name: str, mesh, centroid, source: str = "") -> None:
    """Size, cross-section and body-anterior checks of one vertebra (reference frame, metres)."""
    where = f"{name} mesh{f' ({source})' if source else ''}"
    ext = float(np.max(mesh.extents))
    if ext < MIN_EXTENT_M:
        raise GeometryError(f"{where}: largest extent {ext:.4g} m is below {MIN_EXTENT_M} m; expected a vertebra "
                            "in metres (a lumbar vertebra spans 0.05-0.1 m; was it scaled down twice?)")
    if ext > MAX_EXTENT_M:
        raise GeometryError(f"{where}: largest extent {ext:.4g} m exceeds {MAX_EXTENT_M} m; looks like "
                            "millimetres, expected metres")
    areas = _closed_loop_areas(mesh, centroid)
    if not areas or max(areas) < MIN_SECTION_M2:
        got = f"largest closed loop {max(areas) * 1e4:.3g} cm^2" if areas else "no closed loop"
        raise GeometryError(f"{where}: the horizontal cross-section through the vertebral-body centroid has "
                            f"{got}; expected a surface closed enough for a cross-section of at least "
                            f"{MIN_SECTION_M2 * 1e4:.0f} cm^2")
    bb_centre_x = 0.5 * (mesh.bounds[0, 0] + mesh.bounds[1, 0])
    if not np.asarray(centroid)[0] > bb_centre_x:
        raise GeometryError(f"{where}: the vertebral body (x = {centroid[0]:.4f} m) is not anterior of the "
                            f"bounding-box centre (x = {bb_centre_x:.4f} m); expected the project frame "
                            "(x anterior, y left, z superior)")


def check_spine(geo) -> None:
    """``check_vertebra`` for every vertebra, the vertebrae stacked along +z (S1 lowest), insertions on them."""
    for name, v in geo.vertebrae.items():
        check_vertebra(name, v.mesh, v.centroid, getattr(geo, "name", ""))
    present = [n for n in ORDER if n in geo.vertebrae]
    for lo, up in zip(present, present[1:]):
        d = np.asarray(geo.vertebrae[up].centroid) - np.asarray(geo.vertebrae[lo].centroid)
        if not (d[2] > 0 and abs(d[2]) > max(abs(d[0]), abs(d[1]))):
            raise GeometryError(f"{up} is not above {lo} along +z (centroid difference {np.round(d, 4).tolist()} m); "
                                "expected the project frame (x anterior, y left, z superior)")
    check_insertions(geo)
