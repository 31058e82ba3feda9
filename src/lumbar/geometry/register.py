"""Surface registration of one vertebra onto another (project frame, metres): similarity ICP, affine ICP, then a
smooth non-rigid step (Gaussian radial-basis displacement field on control points, coarse to fine), all with
symmetric closest-point pairs (every template point to its nearest target point and every target point to its
nearest template point, so that neither surface can collapse onto part of the other). Given the target's vertex
normals, each pair pulls only along the target's normal (point to plane, :data:`TANGENTIAL`), and given the whole
target surface (``dense``) each template point is paired on it rather than on the target's sample: the warp then
follows the surface, not the vertices that happened to be sampled.

:func:`register` returns a :class:`Warp` that maps any point near the template (a landmark) into the target.
Deterministic: the same inputs give the same warp; and equivariant: moving both inputs by one rigid motion moves
the warp's output by it (every step uses distances and least squares only).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: (RBF width [m], regularisation, iterations) of the non-rigid stages, coarse to fine
NONRIGID_STAGES = ((0.016, 1e-2, 8), (0.010, 1e-2, 8), (0.006, 3e-2, 8))
N_CONTROL = 150
TRIM = 1.0          # pairs beyond this quantile of the distance are left out
#: weight of the tangential part of a pair's offset when the target's normals are given: 0 pairs each point with
#: the tangent plane at its closest target point (point to plane), 1 with the point itself (point to point). On a
#: sample of 1,500 vertices (about 2.5 mm apart) point-to-point pairs pull the template along the surface towards
#: whichever vertices were sampled: two equally valid samples of the same surface gave landmarks a median 1.1-1.2 mm
#: apart (Visible Human, leave one out); point to plane with the pairs on the whole surface, 0.27-0.31 mm
#: (docs/specimen.md, "Sampling")
TANGENTIAL = 0.0


@dataclass
class Warp:
    A: np.ndarray           # (3, 3) linear part of the affine stage
    t: np.ndarray           # (3,)
    stages: list            # per non-rigid stage (controls (K, 3), weights (K, 3), RBF width [m])
    scale: float            # similarity scale of the first stage (template -> target size)
    rms_m: float            # final symmetric rms pair distance (trimmed)

    def __call__(self, P) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(P, float)) @ self.A.T + self.t
        for C, W, s in self.stages:
            Q = Q + _kernel(Q, C, s) @ W
        return Q


def surface_sample(vertices, n: int, return_index: bool = False, weights=None):
    """At most ``n`` of a surface's ``vertices``, chosen independently of their order in the file and of the pose.

    The vertices are ordered by their distance from the vertices' mean (rounded to 1 nm; ties by coordinates). Without
    ``weights`` every k-th is taken (k = ceil(len / n)); with ``weights`` (each vertex's share of the surface area,
    :func:`mesh_sample`) the vertex at each n-th of the cumulative weight along that order, so that the sample is
    even over the surface whatever the tessellation's density. A stride in file order would make the result depend
    on how the exporter or the reader (STL, OBJ, PLY and VTK differ) happened to number the vertices; the distance
    from the mean is unchanged by a rigid motion and by renumbering, so only the surface itself decides the sample."""
    v = np.asarray(vertices, float)
    r = np.round(np.linalg.norm(v - v.mean(0), axis=1) / 1e-9)
    order = np.lexsort((v[:, 2], v[:, 1], v[:, 0], r))
    if weights is None or len(v) <= n:
        idx = order[::max(1, int(np.ceil(len(v) / n)))]
    else:
        c = np.cumsum(np.asarray(weights, float)[order])
        idx = order[np.unique(np.minimum(np.searchsorted(c, (np.arange(n) + 0.5) * c[-1] / n), len(v) - 1))]
    return (v[idx], idx) if return_index else v[idx]


def welded(mesh):
    """The surface with coincident vertices merged (a file may repeat a vertex per face, as the Visible Human OBJ
    files do): its samples and vertex normals are then the surface's, not the file's."""
    m = mesh.copy()
    m.merge_vertices()
    return m


def mesh_sample(mesh, n: int):
    """(points, indices into ``mesh.vertices``) of an area-even :func:`surface_sample` of a (welded) mesh: each
    vertex weighted by a third of the area of its faces."""
    faces = np.asarray(mesh.faces)
    w = np.bincount(faces.ravel(), weights=np.repeat(np.asarray(mesh.area_faces), 3),
                    minlength=len(mesh.vertices)) / 3.0
    return surface_sample(mesh.vertices, n, return_index=True, weights=w)


def _kernel(P, C, s):
    """Gaussian RBF values (n, k) of points P (n, 3) at the controls C (k, 3), width ``s`` [m]. The squared distances
    by |p|^2 + |c|^2 - 2 p.c on coordinates centred at the controls' mean (one matrix product instead of an (n, k, 3)
    difference array: five times faster; within 1e-14 of the direct form at these sizes, tests/test_specimen.py)."""
    m = C.mean(0)
    Pc, Cc = P - m, C - m
    d2 = (Pc * Pc).sum(1)[:, None] + (Cc * Cc).sum(1)[None, :] - 2.0 * (Pc @ Cc.T)
    np.maximum(d2, 0.0, out=d2)
    return np.exp((-0.5 / (s * s)) * d2)


def _pairs(X, Y, tree_y, normals=None, dense=None):
    """Symmetric closest-point pairs (source indices, target points, rms distance), trimmed at ``TRIM`` per
    direction. With target ``normals`` the tangential part of each pair's offset is weighted by ``TANGENTIAL`` (0:
    point to plane). ``dense`` = (points, normals, tree) of the whole target surface: each source point is paired
    with its closest point there (the reverse pairs stay on the sample Y)."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    Yf, Nf, tree_f = (Y, normals, tree_y) if dense is None else dense
    d1, j = tree_f.query(X)
    d2, i = cKDTree(X).query(Y)
    if TRIM < 1.0:
        k1, k2 = d1 <= np.quantile(d1, TRIM), d2 <= np.quantile(d2, TRIM)
    else:
        k1, k2 = np.ones(len(d1), bool), np.ones(len(d2), bool)
    src = np.r_[np.flatnonzero(k1), i[k2]]
    tgt = np.vstack([Yf[j[k1]], Y[k2]])
    if normals is not None and TANGENTIAL < 1.0:
        N = np.vstack([Nf[j[k1]], normals[k2]])
        off = tgt - X[src]
        along = (off * N).sum(1, keepdims=True) * N
        tgt = X[src] + along + TANGENTIAL * (off - along)
    return src, tgt, float(np.sqrt(0.5 * (np.mean(d1[k1] ** 2) + np.mean(d2[k2] ** 2))))


def _umeyama(P, Q):
    """Similarity (s, R, t) minimising |s R P + t - Q|^2."""
    mp, mq = P.mean(0), Q.mean(0)
    Pc, Qc = P - mp, Q - mq
    U, S, Vt = np.linalg.svd(Qc.T @ Pc / len(P))
    D = np.eye(3)
    if np.linalg.det(U @ Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / (Pc ** 2).sum(1).mean())
    return s, R, mq - s * R @ mp


def farthest_points(X, k):
    """Deterministic farthest-point sample of ``k`` rows of X (starting from the point farthest from the centroid)."""
    k = min(k, len(X))
    idx = [int(np.argmax(((X - X.mean(0)) ** 2).sum(1)))]
    d = ((X - X[idx[0]]) ** 2).sum(1)
    for _ in range(k - 1):
        idx.append(int(np.argmax(d)))
        d = np.minimum(d, ((X - X[idx[-1]]) ** 2).sum(1))
    return X[idx]


METHODS = ("full", "translation")


def register(X, Y, iterations=(15, 10), method: str = "full", normals=None, dense=None) -> Warp:
    """Warp the template points X (n,3) onto the target points Y (m,3); both roughly in the same frame.

    ``method``: "full" (similarity, affine, non-rigid) or "translation" (the centroids made to coincide, nothing
    else: the control of the accuracy measurement, an atlas without registration)."""
    from scipy.spatial import cKDTree  # noqa: PLC0415
    if method not in METHODS:
        raise ValueError(f"registration method {method!r}; expected one of {METHODS}")
    tree = cKDTree(Y)
    if dense is not None and len(dense) == 2:
        dense = (np.asarray(dense[0], float), np.asarray(dense[1], float), cKDTree(dense[0]))
    A, t = np.eye(3), Y.mean(0) - X.mean(0)
    scale = 1.0
    if method == "translation":
        return Warp(A=A, t=t, stages=[], scale=scale, rms_m=_pairs(X + t, Y, tree)[2])
    for _ in range(iterations[0]):                      # similarity ICP
        Xc = X @ A.T + t
        src, tgt, _ = _pairs(Xc, Y, tree, normals, dense)
        s, R, tt = _umeyama(Xc[src], tgt)
        A, t = s * R @ A, s * R @ t + tt
    scale = float(np.cbrt(np.linalg.det(A)))
    for _ in range(iterations[1]):                      # affine ICP
        Xc = X @ A.T + t
        src, tgt, _ = _pairs(Xc, Y, tree, normals, dense)
        H = np.c_[X[src], np.ones(len(src))]
        M, *_ = np.linalg.lstsq(H, tgt, rcond=None)
        A, t = M[:3].T, M[3]
    Q = X @ A.T + t
    C = farthest_points(Q, N_CONTROL)
    stages = []
    for s_rbf, lam, n_it in NONRIGID_STAGES:
        K = _kernel(Q, C, s_rbf)
        W = np.zeros((len(C), 3))
        for _ in range(n_it):
            src, tgt, _ = _pairs(Q + K @ W, Y, tree, normals, dense)
            # the normal equations of the pairs, summed per template point (a point paired several times counts as
            # often): K^T diag(count) K and K^T (summed offsets), on the n template rows instead of the pairs
            count = np.bincount(src, minlength=len(Q)).astype(float)
            off = np.zeros_like(Q)
            np.add.at(off, src, tgt - Q[src])
            G = K.T @ (count[:, None] * K) + lam * len(src) / len(C) * np.eye(len(C))
            W = np.linalg.solve(G, K.T @ off)
        stages.append((C, W, s_rbf))
        Q = Q + K @ W
        C = C + _kernel(C, C, s_rbf) @ W
    _, _, rms = _pairs(Q, Y, tree)
    return Warp(A=A, t=t, stages=stages, scale=scale, rms_m=rms)
