"""Bone features of one vertebra in the project frame (x anterior, y left, z superior, metres): points a CT shows
on any vertebra, measured the same way on an atlas template and on a user's specimen, that anchor the carried
insertion groups of :mod:`lumbar.geometry.specimen_landmarks` where the warp of the whole vertebra misses the
processes (docs/specimen.md, "Bone-feature anchors").

Every feature is the mean of a band of surface vertices, not one vertex, so that a staircase surface (marching
cubes on a label map) or a coarser mesh moves it by a fraction of its spacing:

* ``transverse_tip`` (ITL): the lateral end of the posterior elements on one side (vertices behind the body within
  :data:`BAND_M` of the most lateral one): the tip of the transverse process on a lumbar vertebra.
* ``spinous_edge`` (ISL): the spinous process's inferior edge (role "upper") or superior edge (role "lower") on the
  mid-sagittal band, between :data:`SPINOUS_SPAN` of the way from the lamina's anterior edge to the tip, where the
  interspinous fibres insert.
* ``spinous_tip`` (SSL): the posterior end of the spinous process on the mid-sagittal band.
* ``lamina_edge`` (FL): the inferior (upper role) or superior (lower role) edge of the laminae within
  :data:`LAMINA_HALF_WIDTH_M` of the midline, behind the canal's posterior wall.
* ``body_corner`` (ALL): the anterior-inferior (upper role) or anterior-superior (lower role) corner of the
  vertebral body on the mid-sagittal band (the vertices within :data:`BAND_M` of the extreme of x -/+ z).

A feature that cannot be found (no mid-sagittal section, an empty band) is ``None``: the group keeps the plain
atlas transfer.
"""
from __future__ import annotations

import numpy as np

BAND_M = 1.5e-3                 # vertices within this of an extreme form a feature's band
MIDLINE_HALF_WIDTH_M = 4e-3     # the mid-sagittal band of the spinous process and the body
LAMINA_HALF_WIDTH_M = 8e-3      # the laminae's band about the midline (the flavum's three fibres at -6, 0, +6 mm)
LAMINA_DEPTH_M = (8e-3, 2e-3)   # lamina window: from 8 mm behind to 2 mm in front of its anterior edge
SPINOUS_SPAN = (0.25, 0.75)     # the interspinous fibres' share of the process, lamina -> tip
EDGE_BIN_M = 2e-3               # x bins along a process whose lowest/highest vertex traces its edge

#: the feature that anchors each insertion group: {ligament: feature}
FEATURE_OF = {"ITL_L": "transverse_tip", "ITL_R": "transverse_tip", "ISL": "spinous_edge", "SSL": "spinous_tip",
              "FL": "lamina_edge", "ALL": "body_corner"}


def _split(mesh, cache: dict):
    """(x of the body's posterior wall, x of the lamina's anterior edge) on the mid-sagittal section, cached."""
    if "split" not in cache:
        from .analysis import sagittal_split  # noqa: PLC0415 - trimesh section, imported where used
        try:
            cache["split"] = sagittal_split(mesh)
        except (ValueError, IndexError):
            cache["split"] = (None, None)
    return cache["split"]


def _band_mean(P, score):
    """Mean of the points within BAND_M of the largest ``score``."""
    if len(P) == 0:
        return None
    return P[score > score.max() - BAND_M].mean(0)


def _edge(P, lower: bool):
    """Mean over the EDGE_BIN_M x bins of the lowest (``lower``) or highest band of points in each (within BAND_M of
    the bin's extreme): a process's edge, sampled evenly along it however dense the mesh is there."""
    if len(P) < 3:
        return None
    b = np.floor(P[:, 0] / EDGE_BIN_M).astype(int)
    pts = []
    for k in np.unique(b):
        Q = P[b == k]
        z = -Q[:, 2] if lower else Q[:, 2]
        pts.append(Q[z > z.max() - BAND_M].mean(0))
    return np.mean(pts, axis=0)


def feature_point(mesh, structure: str, role: str, cache: dict | None = None):
    """The feature anchoring ``structure``'s ends of ``role`` ("upper": the vertebra is the level's upper body) on
    ``mesh`` (project frame), a (3,) array in metres, or None (module doc)."""
    name = FEATURE_OF.get(structure)
    if name is None:
        return None
    cache = {} if cache is None else cache
    key = (name, structure, role)
    if key in cache:
        return cache[key]
    V = np.asarray(mesh.vertices, float)
    x_post, x_lam = _split(mesh, cache)
    out = None
    if x_post is not None and x_lam is not None:
        upper = role == "upper"
        if name == "transverse_tip":
            s = 1.0 if structure.endswith("_L") else -1.0
            P = V[V[:, 0] < x_post - 2e-3]
            out = _band_mean(P, s * P[:, 1]) if len(P) else None
        elif name in ("spinous_edge", "spinous_tip"):
            P = V[(np.abs(V[:, 1]) < MIDLINE_HALF_WIDTH_M) & (V[:, 0] < x_lam - 3e-3)]
            if len(P):
                tip = P[:, 0].min()
                if name == "spinous_tip":
                    out = _band_mean(P, -P[:, 0])
                else:
                    f = (P[:, 0] - x_lam) / (tip - x_lam)
                    out = _edge(P[(f >= SPINOUS_SPAN[0]) & (f <= SPINOUS_SPAN[1])], lower=upper)
        elif name == "lamina_edge":
            P = V[(np.abs(V[:, 1]) < LAMINA_HALF_WIDTH_M) & (V[:, 0] > x_lam - LAMINA_DEPTH_M[0])
                  & (V[:, 0] < x_lam + LAMINA_DEPTH_M[1])]
            if len(P) >= 3:
                Q = P[:, [1, 0, 2]]            # bins along y: the edge across the laminae
                e = _edge(Q, lower=upper)
                out = None if e is None else e[[1, 0, 2]]
        elif name == "body_corner":
            P = V[(np.abs(V[:, 1]) < MIDLINE_HALF_WIDTH_M) & (V[:, 0] > x_post)]
            out = _band_mean(P, P[:, 0] + (-1.0 if upper else 1.0) * P[:, 2]) if len(P) else None
    cache[key] = None if out is None else np.asarray(out, float)
    return cache[key]
