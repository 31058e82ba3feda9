"""Mirror-averaging of a spine geometry about the mid-sagittal plane y = 0 (project frame, docs/design.md).

The landmarks of a segmented (or mesh-derived) spine are never exactly bilateral: the myo-sim meshes and
the rules that place the ligament insertions and facet grids on them give left and right structures that
differ by a few millimetres, so at the reference pose the passive elements push the vertebrae laterally.
For studies whose loading is symmetric and whose other parts are symmetric (e.g. the muscle-driven model,
whose fascicles are mirrored by :func:`lumbar.muscles.muscle_set.load_muscle_set`), this asymmetry is an
artefact; :func:`mirror_average` removes it.

Rule (M = diag(1, -1, 1), the reflection y -> -y):

* every point set whose structure has a left and a right copy (facet superior/inferior grids; the
  ligament pairs CL_L/CL_R, ITL_L/ITL_R) is paired point by point with the mirror image of its partner
  (optimal assignment on the mirrored distance, since the grids of the two sides are not necessarily
  ordered alike); each point becomes ``(p + M p_partner) / 2`` and its partner ``M`` of that;
* the fibres of a midline ligament (ALL, PLL, FL, ISL, SSL) are paired the same way within the ligament,
  upper and lower ends together; a fibre whose best partner is itself (a medial fibre) is projected to
  y = 0 (``(p + M p) / 2``); extra lengths are averaged over each pair;
* disc centres and vertebral-body centroids are projected to y = 0, disc normals have their y component
  removed and are renormalised; disc areas and heights (scalars) are unchanged; meshes are not touched
  (they only carry the visual surface).

The result is exactly mirror-symmetric (``asymmetry(mirror_average(g)) == 0`` to round-off).
"""
from __future__ import annotations

import copy

import numpy as np

from .core import FacetLandmarks, Level, Ligament, SpineGeometry, Vertebra

M = np.array([1.0, -1.0, 1.0])
PAIRED_LIGAMENTS = (("CL_L", "CL_R"), ("ITL_L", "ITL_R"))


def _pairing(A, B):
    """Index j(i) of the point (row) of B closest to the mirror image of row i of A (optimal assignment).

    A, B: (n, k) arrays of stacked points (k = 3 per point, 6 for a fibre's two ends)."""
    from scipy.optimize import linear_sum_assignment  # noqa: PLC0415 - scipy.optimize (about a second) only where a fit runs
    MA = A * np.tile(M, A.shape[1] // 3)
    cost = np.linalg.norm(MA[:, None, :] - B[None, :, :], axis=-1)
    rows, cols = linear_sum_assignment(cost)
    j = np.empty(len(A), int)
    j[rows] = cols
    return j


def _average_pair(A, B):
    """Mirror-average two point sets (n, 3k) of the two sides: returns (A', B') with B' = M A' exactly."""
    if A.shape != B.shape:
        raise ValueError(f"left/right structures have different shapes {A.shape} and {B.shape}")
    j = _pairing(A, B)
    Mk = np.tile(M, A.shape[1] // 3)
    A2 = 0.5 * (A + B[j] * Mk)
    B2 = np.empty_like(B)
    B2[j] = A2 * Mk
    return A2, B2, j


def _average_within(P):
    """Mirror-average one midline point set (n, 3k): the set becomes its own mirror image."""
    j = _pairing(P, P)
    Mk = np.tile(M, P.shape[1] // 3)
    return 0.5 * (P + P[j] * Mk), j


def _level(lev: Level) -> Level:
    out = copy.copy(lev)
    c = np.array(lev.disc_centre, float)
    c[1] = 0.0
    n = np.array(lev.disc_normal, float)
    n[1] = 0.0
    out.disc_centre, out.disc_normal = c, n / np.linalg.norm(n)
    if lev.facets:
        if set(lev.facets) != {"left", "right"}:
            raise ValueError(f"level {lev.name}: facets on one side only ({sorted(lev.facets)}); cannot mirror")
        L, R = lev.facets["left"], lev.facets["right"]
        sl, sr, _ = _average_pair(L.superior, R.superior)
        il, ir, _ = _average_pair(L.inferior, R.inferior)
        cl = cr = None
        if L.contact_points is not None and R.contact_points is not None:
            # the union of the left face's points and the mirrored right face's: the same set on both sides
            cl = np.vstack([L.contact_points, R.contact_points * M])
            cr = cl * M
        out.facets = {"left": FacetLandmarks(superior=sl, inferior=il, contact=L.contact, contact_points=cl),
                      "right": FacetLandmarks(superior=sr, inferior=ir, contact=R.contact, contact_points=cr)}
    ligs = {g.name: g for g in lev.ligaments}
    new = {}
    for a, b in PAIRED_LIGAMENTS:
        if (a in ligs) != (b in ligs):
            raise ValueError(f"level {lev.name}: ligament {a if a in ligs else b} has no mirrored partner")
        if a in ligs:
            la, lb = ligs[a], ligs[b]
            A2, B2, j = _average_pair(np.hstack([la.upper, la.lower]), np.hstack([lb.upper, lb.lower]))
            ea = 0.5 * (la.extra_length + lb.extra_length[j])
            eb = np.empty_like(ea)
            eb[j] = ea
            new[a] = Ligament(a, la.kind, A2[:, :3], A2[:, 3:], ea)
            new[b] = Ligament(b, lb.kind, B2[:, :3], B2[:, 3:], eb)
    for name, g in ligs.items():
        if name in new:
            continue
        P2, j = _average_within(np.hstack([g.upper, g.lower]))
        new[name] = Ligament(name, g.kind, P2[:, :3], P2[:, 3:], 0.5 * (g.extra_length + g.extra_length[j]))
    out.ligaments = [new[g.name] for g in lev.ligaments]
    return out


def mirror_average(geometry: SpineGeometry) -> SpineGeometry:
    """A copy of ``geometry`` made exactly mirror-symmetric about y = 0 (module docstring)."""
    verts = {}
    for name, v in geometry.vertebrae.items():
        c = np.array(v.centroid, float)
        c[1] = 0.0
        verts[name] = Vertebra(name=v.name, mesh=v.mesh, centroid=c)
    levels = {name: _level(lev) for name, lev in geometry.levels.items()}
    return SpineGeometry(name=f"{geometry.name}_mirror_averaged",
                         source=f"{geometry.source}; mirror-averaged about y = 0 (lumbar.geometry.symmetry)",
                         vertebrae=verts, levels=levels)


def asymmetry(geometry: SpineGeometry) -> float:
    """Largest distance [m] between a passive-element point and the mirror image of its partner (0 when the
    geometry is mirror-symmetric): facets, ligament fibres, disc centres/normals, body centroids."""
    err = 0.0
    for v in geometry.vertebrae.values():
        err = max(err, abs(float(v.centroid[1])))
    for lev in geometry.levels.values():
        err = max(err, abs(float(lev.disc_centre[1])), abs(float(lev.disc_normal[1])))
        if lev.facets:
            L, R = lev.facets["left"], lev.facets["right"]
            for a, b in ((L.superior, R.superior), (L.inferior, R.inferior)):
                j = _pairing(a, b)
                err = max(err, float(np.abs(a * M - b[j]).max()))
        ligs = {g.name: g for g in lev.ligaments}
        done = set()
        for a, b in PAIRED_LIGAMENTS:
            if a in ligs and b in ligs:
                A, B = np.hstack([ligs[a].upper, ligs[a].lower]), np.hstack([ligs[b].upper, ligs[b].lower])
                j = _pairing(A, B)
                err = max(err, float(np.abs(A * np.tile(M, 2) - B[j]).max()))
                done |= {a, b}
        for name, g in ligs.items():
            if name in done:
                continue
            P = np.hstack([g.upper, g.lower])
            j = _pairing(P, P)
            err = max(err, float(np.abs(P * np.tile(M, 2) - P[j]).max()))
    return err
