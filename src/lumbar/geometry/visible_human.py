"""Visible Human Male lumbosacral geometry (Remus et al. 2021, ArtiSynth model; BSD-3-Clause).

Read from a folder laid out as ``../shared/geometry/visible_human_lss`` (see its README.md); nothing is
copied.  All files are already in the project frame (x anterior, y left, z superior; metres) -- checked
in tests/test_geometry.py.

Choices (documented, see also the report in the package docs):
- vertebra mesh ``meshes/Lk_vertebra.obj``; centroid = volume centroid of the convex hull of
  ``meshes/Lk_body.obj`` (the body meshes are not watertight);
- disc centre = mean of all nucleus + annulus nodes; disc normal = smallest-variance principal axis of
  those nodes, oriented +z; disc height = extent along the normal of the nucleus nodes within 3 mm of the
  disc axis (gap between the endplates at the centre); disc CSA = convex-hull area of the outermost
  annulus ring's nodes projected on the mid-disc plane;
- AS ligaments: each fibre is oriented so that ``upper`` is the end nearer the upper vertebra mesh;
- MP ligaments (ALL, PLL with via points): points are assigned to the upper/lower vertebra by the side of
  the mid-disc plane; the segment crossing the plane is the point-to-point part and the summed length of
  all other segments goes into ``extra_length``;
- facets: each ``facet_fe/LIJ_FAC{L,R}_Lk.node`` is one thin wedge-element cartilage layer spanning the
  joint; its nodes are split by which vertebra mesh they are nearer (upper -> inferior articular process,
  lower -> superior articular process); on each part a 3x3 grid (10/50/90 % quantiles of the two major
  principal axes) is snapped to the nearest distinct node.  ``*_WED`` files (L4-L5 only) are ignored.
"""
from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from . import analysis as A
from . import diskcache
from .core import (FacetLandmarks, GeometryError, Level, Ligament, SpineGeometry, Vertebra, level_vertebrae,
                   levels_and_vertebrae)
from .meshio import read_mesh, require_dir

PREFIX = {"L1-L2": "L12", "L2-L3": "L23", "L3-L4": "L34", "L4-L5": "L45", "L5-S1": "L51"}
NAME_MAP = {"LF": "FL"}
AS_NAMES = ("CL_R", "CL_L", "LF", "ISL", "SSL", "ITL_R", "ITL_L")
MP_NAMES = ("ALL", "PLL")
NP_AXIS_RADIUS = 0.003
MAX_COORD_M = 2.0   # m: a node or fibre point further from the origin is in the wrong unit (the set lies within 0.2 m)


def _numbers(text: str):
    return [float(t) for t in text.replace(",", " ").replace("\t", " ").split()]


@functools.lru_cache(maxsize=64)
def _read_nodes_cached(path: str, mtime: int) -> np.ndarray:
    # parsed once per file content across processes (lumbar.geometry.diskcache)
    tag = f"index x y z, |coordinate| <= {MAX_COORD_M} m"
    return diskcache.load_or_parse(path, "nodes", tag, lambda: {"nodes": _parse_nodes(path)})["nodes"]


def _parse_nodes(path: str) -> np.ndarray:
    rows = []
    with open(path) as fh:
        for ln, line in enumerate(fh, 1):
            if not line.strip():
                continue
            try:
                vals = _numbers(line)
            except ValueError:
                raise GeometryError(f"{path}: line {ln}: expected 'index x y z' numbers, got {line.strip()!r}")
            if len(vals) != 4:
                raise GeometryError(f"{path}: line {ln}: expected 4 numbers 'index x y z', got {len(vals)}")
            if not np.all(np.isfinite(vals)):
                raise GeometryError(f"{path}: line {ln}: non-finite coordinate in {line.strip()!r}; expected finite "
                                    "'index x y z' numbers (metres)")
            if max(abs(v) for v in vals[1:]) > MAX_COORD_M:
                raise GeometryError(f"{path}: line {ln}: coordinate {max(vals[1:], key=abs):g} is beyond "
                                    f"{MAX_COORD_M:g} m (millimetres?); expected 'index x y z' in metres")
            rows.append(vals[1:])
    if not rows:
        raise GeometryError(f"{path}: no nodes (expected lines 'index x y z')")
    return np.array(rows)


def read_nodes(path) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise GeometryError(f"{p}: node file missing (expected lines 'index x y z' in metres)")
    return _read_nodes_cached(str(p.resolve()), os.stat(p).st_mtime_ns).copy()


@functools.lru_cache(maxsize=64)
def _read_lig_cached(path: str, mtime: int, kind: str) -> tuple:
    """Parse a .lig file -> tuple of (name, array) ; AS: (n,6) ; MP: (n, n_points, 3)."""
    with open(path) as fh:
        lines = [(i, ln.strip()) for i, ln in enumerate(fh, 1) if ln.strip()]
    if not lines:
        raise GeometryError(f"{path}: empty .lig file")
    i0, first = lines[0]
    try:
        n_lig = int(first.split(",")[0])
    except ValueError:
        raise GeometryError(f"{path}: line {i0}: expected the number of ligaments, got {first!r}")
    out, k = [], 1
    form = "NAME, n_fibres, reference_length_m" if kind == "AS" else "NAME, n_fibres, n_points"
    for _ in range(n_lig):
        if k >= len(lines):
            raise GeometryError(f"{path}: file ends early; expected {n_lig} ligaments")
        ln, head = lines[k]
        parts = [t.strip() for t in head.split(",") if t.strip()]
        try:
            if len(parts) != 3 or not parts[0][0].isalpha():
                raise ValueError
            name, nf = parts[0], int(parts[1])
            third = float(parts[2])
        except (ValueError, IndexError):
            raise GeometryError(f"{path}: line {ln}: expected header '{form}', got {head!r}")
        npts = 2 if kind == "AS" else int(third)
        rows = []
        for j in range(nf):
            k += 1
            if k >= len(lines):
                raise GeometryError(f"{path}: file ends inside {name}; expected {nf} fibre lines")
            ln, line = lines[k]
            try:
                vals = _numbers(line)
            except ValueError:
                raise GeometryError(f"{path}: line {ln} ({name} fibre {j + 1}): expected {3 * npts} numbers "
                                    f"(x, y, z per point, metres), got {line!r}")
            if len(vals) != 3 * npts:
                raise GeometryError(f"{path}: line {ln} ({name} fibre {j + 1}): expected {3 * npts} numbers "
                                    f"({npts} points x, y, z in metres), got {len(vals)}")
            if not np.all(np.isfinite(vals)):
                raise GeometryError(f"{path}: line {ln} ({name} fibre {j + 1}): non-finite coordinate in "
                                    f"{line!r}; expected finite x, y, z numbers (metres)")
            if max(abs(v) for v in vals) > MAX_COORD_M:
                raise GeometryError(f"{path}: line {ln} ({name} fibre {j + 1}): coordinate "
                                    f"{max(vals, key=abs):g} is beyond {MAX_COORD_M:g} m (millimetres?); "
                                    "expected x, y, z in metres")
            rows.append(np.array(vals).reshape(npts, 3))
        k += 1
        out.append((name, np.array(rows)))
    return tuple(out)


def read_lig(path, kind: str):
    p = Path(path)
    if not p.is_file():
        raise GeometryError(f"{p}: ligament file missing")
    return [(n, a.copy()) for n, a in _read_lig_cached(str(p.resolve()), os.stat(p).st_mtime_ns, kind)]


def _strip(name: str, prefix: str) -> str:
    base = name[len(prefix) + 1:] if name.startswith(prefix + "_") else name
    return NAME_MAP.get(base, base)


def _disc(folder: Path, pre: str):
    npn = read_nodes(folder / "disc_fe" / f"{pre}_NP.node")
    rings = [read_nodes(folder / "disc_fe" / f"{pre}_AN_R{r}.node") for r in (1, 2, 3, 4)]
    allp = np.vstack([npn] + rings)
    c, n = A.plane_fit(allp)
    def radius(p):
        d = p - c
        return np.linalg.norm(d - np.outer(d @ n, n), axis=1).mean()
    outer = max(rings, key=radius)
    csa = A.projected_area(outer, n)
    d = npn - c
    h = d @ n
    r = np.linalg.norm(d - np.outer(h, n), axis=1)
    near = h[r < NP_AXIS_RADIUS] if (r < NP_AXIS_RADIUS).sum() >= 2 else h[np.argsort(r)[:10]]
    return c, n, float(csa), float(near.max() - near.min())


def _grid_on_nodes(nodes: np.ndarray) -> np.ndarray:
    c = nodes.mean(axis=0)
    _, _, vt = np.linalg.svd(nodes - c, full_matrices=False)
    e1, e2 = vt[0], vt[1]
    if e1[2] < 0:
        e1 = -e1
    if e2[0] < 0:
        e2 = -e2
    q1, q2 = (nodes - c) @ e1, (nodes - c) @ e2
    a1 = np.quantile(q1, [0.9, 0.5, 0.1])
    a2 = np.quantile(q2, [0.1, 0.5, 0.9])
    pts, used = [], set()
    from scipy.spatial import cKDTree  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    tree = cKDTree(nodes)
    for s1 in a1:
        for s2 in a2:
            t = c + s1 * e1 + s2 * e2
            _, idx = tree.query(t, k=min(len(nodes), 12))
            i = next(int(j) for j in np.atleast_1d(idx) if int(j) not in used)
            used.add(i)
            pts.append(nodes[i])
    return np.array(pts)


def _split_joint_layer(nodes: np.ndarray, tree_upper, tree_lower):
    """Split the nodes of one facet-joint cartilage layer into (upper face, lower face).

    The layer spans the joint: two node sheets about 1.8 mm apart at L4-L5 (the lumbar facet joint space is
    1.5-1.9 mm, data/anatomy/). The nodes are split by the sign of their offset along the layer's
    least-variance axis (the joint normal). Lumbar anatomy: the lower vertebra's superior articular process
    lies lateral to the upper vertebra's inferior articular process, so the medial sheet (smaller mean |y|)
    is the upper vertebra's face. (For every level of the Visible Human set this is also the sheet lying
    deeper inside the upper vertebra's mesh; the unsigned distance to the meshes cannot tell the sheets
    apart: both are 0.3-2 mm from each mesh.) Splitting node by node by the nearer mesh, the former rule,
    mixed the two sheets and put landmarks of the upper process below the joint surface.
    """
    cc, nn = A.plane_fit(nodes)
    t = (nodes - cc) @ nn
    on_a, on_b = nodes[t > 0], nodes[t <= 0]
    if len(on_a) < 9 or len(on_b) < 9:
        raise GeometryError(f"facet cartilage layer with {len(nodes)} nodes does not split into two sheets of "
                            ">= 9 nodes along its normal (got {len(on_a)} and {len(on_b)})")
    if np.abs(on_a[:, 1]).mean() < np.abs(on_b[:, 1]).mean():
        return on_a, on_b
    return on_b, on_a


def load_visible_human(path, levels=None) -> SpineGeometry:
    if not Path(path).is_dir():
        raise GeometryError(f"{path}: visible_human geometry directory missing; expected the visible_human_lss "
                            "folder (workflow config key geometry.path, or path= of load_geometry)")
    folder = require_dir(path, "visible_human geometry")
    for sub in ("meshes", "ligaments", "disc_fe", "facet_fe"):
        require_dir(folder / sub, f"visible_human '{sub}'")
    levels, verts = levels_and_vertebrae(levels)
    # validate every file before computing anything
    files = [folder / "meshes" / f"{v}_{p}.obj" for v in verts for p in ("vertebra", "body")]
    for lv in levels:
        pre = PREFIX[lv]
        U = level_vertebrae(lv)[0]
        files += [folder / "ligaments" / f"{pre}_Ligs_AS.lig", folder / "ligaments" / f"{pre}_Ligs_MP.lig",
                  folder / "disc_fe" / f"{pre}_NP.node"]
        files += [folder / "disc_fe" / f"{pre}_AN_R{r}.node" for r in (1, 2, 3, 4)]
        files += [folder / "facet_fe" / f"{pre}_FAC{s}_{U}.node" for s in "LR"]
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise GeometryError(f"visible_human: missing file(s): {missing}")
    meshes = {v: read_mesh(folder / "meshes" / f"{v}_vertebra.obj") for v in verts}
    bodies = {v: read_mesh(folder / "meshes" / f"{v}_body.obj") for v in verts}
    ligfiles = {lv: (read_lig(folder / "ligaments" / f"{PREFIX[lv]}_Ligs_AS.lig", "AS"),
                     read_lig(folder / "ligaments" / f"{PREFIX[lv]}_Ligs_MP.lig", "MP")) for lv in levels}
    from scipy.spatial import cKDTree  # noqa: PLC0415
    trees = {v: cKDTree(m.vertices) for v, m in meshes.items()}
    geo_levels = {}
    for lv in levels:
        U, L = level_vertebrae(lv)
        pre = PREFIX[lv]
        c, n, csa, height = _disc(folder, pre)
        ligs = []
        as_ligs, mp_ligs = ligfiles[lv]
        for name, arr in as_ligs:
            nm = _strip(name, pre)
            p1, p2 = arr[:, 0], arr[:, 1]
            d1u, d1l = trees[U].query(p1)[0], trees[L].query(p1)[0]
            d2u, d2l = trees[U].query(p2)[0], trees[L].query(p2)[0]
            swap = (d1l + d2u) < (d1u + d2l)
            up = np.where(swap[:, None], p2, p1)
            lo = np.where(swap[:, None], p1, p2)
            ligs.append(Ligament(nm, nm.split("_")[0], up, lo, np.zeros(len(up))))
        for name, arr in mp_ligs:
            nm = _strip(name, pre)
            ups, los, extra = [], [], []
            for j, pts in enumerate(arr):
                side = (pts - c) @ n > 0
                cross = np.where(side[:-1] != side[1:])[0]
                if len(cross) != 1:
                    raise GeometryError(f"{folder / 'ligaments' / (pre + '_Ligs_MP.lig')}: {name} fibre {j + 1} "
                                        f"crosses the mid-disc plane {len(cross)} times; expected once")
                i = cross[0]
                a, b = pts[i], pts[i + 1]
                seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
                ups.append(a if side[i] else b)
                los.append(b if side[i] else a)
                extra.append(seg.sum() - seg[i])
            ligs.append(Ligament(nm, nm, np.array(ups), np.array(los), np.array(extra)))
        order = {"ALL": 0, "PLL": 1, "FL": 2, "CL_L": 3, "CL_R": 4, "ISL": 5, "SSL": 6, "ITL_L": 7, "ITL_R": 8}
        ligs.sort(key=lambda g: order.get(g.name, 99))
        facets = {}
        for s, side in (("L", "left"), ("R", "right")):
            nodes = read_nodes(folder / "facet_fe" / f"{pre}_FAC{s}_{U}.node")
            on_u, on_l = _split_joint_layer(nodes, trees[U], trees[L])
            facets[side] = FacetLandmarks(superior=_grid_on_nodes(on_l), inferior=_grid_on_nodes(on_u), contact="touching",
                                          contact_points=on_u.copy())
        geo_levels[lv] = Level(lv, U, L, c, n, csa, height, facets, ligs)
    vertebrae = {v: Vertebra(v, meshes[v], A.hull_centroid(bodies[v].vertices)) for v in verts}
    return SpineGeometry(name="visible_human", source=f"Visible Human Male lumbosacral spine (Remus et al. 2021, "
                         f"BSD-3-Clause) from {folder}", vertebrae=vertebrae, levels=geo_levels)


#: the columns of a ``*_UWMat.lig`` row after the name (Remus et al. 2021; data/geometry/visible_human_lss/README.md)
UW_FIELDS = ("reference_strain", "transition_strain", "stiffness_n", "cross_section_mm2")


def read_uw_materials(path, level: str) -> dict:
    """The original model's ligament materials of ``level`` from the ``*_UWMat.lig`` files of a visible_human_lss
    folder: {ligament name as in :func:`load_visible_human` (CL_L, FL, ITL_R, ALL, ...): dict(UW_FIELDS)}.

    Per fibre, Blankevoort/UW law (Remus et al. 2021): rest length l0 = l_geometric * (1 + reference_strain),
    strain e = l / l0 - 1, force 0 (e <= 0), stiffness_n * e**2 / (2 * transition_strain) (e < transition),
    stiffness_n * (e - transition / 2) beyond (:func:`uw_force`). A missing file is an error naming it."""
    folder = Path(path)
    if level not in PREFIX:
        raise GeometryError(f"unknown level {level!r}; expected one of {sorted(PREFIX)}")
    pre = PREFIX[level]
    out = {}
    for part, names in (("AS", AS_NAMES), ("MP", MP_NAMES)):
        f = folder / "ligaments" / f"{pre}_Ligs_{part}_UWMat.lig"
        if not f.is_file():
            raise GeometryError(f"{f}: ligament material file missing (expected the *_UWMat.lig files of the "
                                "Visible Human set)")
        lines = [ln.strip() for ln in f.read_text().splitlines() if ln.strip()]
        try:
            n = int(float(lines[0]))
        except (IndexError, ValueError):
            raise GeometryError(f"{f}: first line must be the number of ligaments") from None
        if len(lines) != n + 1:
            raise GeometryError(f"{f}: {len(lines) - 1} material rows for {n} ligaments")
        for row, ln in enumerate(lines[1:], start=2):
            parts = [p.strip() for p in ln.split(",")]
            if len(parts) != 5:
                raise GeometryError(f"{f}, line {row}: expected 'name, reference strain, transition strain, "
                                    f"stiffness, cross-section', got {ln!r}")
            name = NAME_MAP.get(parts[0].split("_", 1)[1], parts[0].split("_", 1)[1])
            vals = [float(v) for v in parts[1:]]
            if not (vals[1] > 0 and vals[2] >= 0 and vals[3] > 0):
                raise GeometryError(f"{f}, line {row}: transition strain and cross-section must be > 0, stiffness "
                                    f">= 0; got {vals}")
            out[name] = dict(zip(UW_FIELDS, vals))
        missing = [nm for nm in names if NAME_MAP.get(nm, nm) not in out]
        if missing:
            raise GeometryError(f"{f}: no material row for {missing}")
    return out


def uw_force(length, geometric_length, mat: dict):
    """Force [N] of one fibre of the Blankevoort/UW law of :func:`read_uw_materials` at ``length`` [m], for a fibre
    whose length in the geometry is ``geometric_length`` [m] (vectorised)."""
    l0 = np.asarray(geometric_length, float) * (1.0 + mat["reference_strain"])
    e = np.asarray(length, float) / l0 - 1.0
    et, k = mat["transition_strain"], mat["stiffness_n"]
    return np.where(e <= 0, 0.0, np.where(e < et, k * e * e / (2.0 * et), k * (e - 0.5 * et)))
