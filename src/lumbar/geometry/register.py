"""Surface registration of one vertebra onto another (project frame, metres): similarity ICP, affine ICP, then a
smooth non-rigid step (Gaussian radial-basis displacement field on control points, coarse to fine), all with
symmetric closest-point pairs (every template point to its nearest target point and every target point to its
nearest template point, so that neither surface can collapse onto part of the other).

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


def _kernel(P, C, s):
    d2 = ((P[:, None, :] - C[None, :, :]) ** 2).sum(-1)
    return np.exp(-0.5 * d2 / (s * s))


def _pairs(X, Y, tree_y):
    """Symmetric closest-point pairs (source points, target points), trimmed at ``TRIM`` per direction."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    d1, j = tree_y.query(X)
    d2, i = cKDTree(X).query(Y)
    if TRIM < 1.0:
        k1, k2 = d1 <= np.quantile(d1, TRIM), d2 <= np.quantile(d2, TRIM)
    else:
        k1, k2 = np.ones(len(d1), bool), np.ones(len(d2), bool)
    src = np.r_[np.flatnonzero(k1), i[k2]]
    tgt = np.vstack([Y[j[k1]], Y[k2]])
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


def register(X, Y, iterations=(15, 10), method: str = "full") -> Warp:
    """Warp the template points X (n,3) onto the target points Y (m,3); both roughly in the same frame.

    ``method``: "full" (similarity, affine, non-rigid) or "translation" (the centroids made to coincide, nothing
    else: the control of the accuracy measurement, an atlas without registration)."""
    from scipy.spatial import cKDTree  # noqa: PLC0415
    if method not in METHODS:
        raise ValueError(f"registration method {method!r}; expected one of {METHODS}")
    tree = cKDTree(Y)
    A, t = np.eye(3), Y.mean(0) - X.mean(0)
    scale = 1.0
    if method == "translation":
        return Warp(A=A, t=t, stages=[], scale=scale, rms_m=_pairs(X + t, Y, tree)[2])
    for _ in range(iterations[0]):                      # similarity ICP
        Xc = X @ A.T + t
        src, tgt, _ = _pairs(Xc, Y, tree)
        s, R, tt = _umeyama(Xc[src], tgt)
        A, t = s * R @ A, s * R @ t + tt
    scale = float(np.cbrt(np.linalg.det(A)))
    for _ in range(iterations[1]):                      # affine ICP
        Xc = X @ A.T + t
        src, tgt, _ = _pairs(Xc, Y, tree)
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
            src, tgt, _ = _pairs(Q + K @ W, Y, tree)
            Ks = K[src]
            G = Ks.T @ Ks + lam * len(src) / len(C) * np.eye(len(C))
            W = np.linalg.solve(G, Ks.T @ (tgt - Q[src]))
        stages.append((C, W, s_rbf))
        Q = Q + K @ W
        C = C + _kernel(C, C, s_rbf) @ W
    _, _, rms = _pairs(Q, Y, tree)
    return Warp(A=A, t=t, stages=stages, scale=scale, rms_m=rms)
