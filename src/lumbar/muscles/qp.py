"""The QP of the muscle redundancy solver (lumbar.muscles.redundancy): the exact minimiser of a bound-constrained
linear least-squares problem with few residual rows, :func:`box_lsq`."""
from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear


def box_lsq(alpha, C, d, a, lb, ub, max_iter=50, tol=1e-12):
    """Exact minimiser of ``alpha |a + z|^2 + |C z - d|^2`` over ``lb <= z <= ub`` (C: k x n, k << n).

    Solved through its dual in the k residual multipliers y (concave, piecewise quadratic):
    ``z(y) = clip(-a - C^T y / (2 alpha), lb, ub)`` and ``grad = C z(y) - d - y / 2``, maximised by a
    semismooth Newton method with backtracking (generalised Hessian ``-(C_F C_F^T / (2 alpha) + I / 2)``
    on the free set F). Strong duality holds (strictly convex primal), so z(y*) is the primal minimiser.
    Falls back to BVLS (scipy.optimize.lsq_linear) if the dual iteration does not converge."""
    k = C.shape[0]
    y = np.zeros(k)

    def zf(y):
        return np.clip(-a - C.T @ y / (2 * alpha), lb, ub)

    def dual(y, z):
        return alpha * np.sum((a + z) ** 2) + y @ (C @ z - d) - y @ y / 4

    scale = 1.0 + np.abs(d).max() + np.abs(C).max()
    z = zf(y)
    gval = dual(y, z)
    for _ in range(max_iter):
        grad = C @ z - d - y / 2
        if np.abs(grad).max() < tol * scale:
            return z
        u = -a - C.T @ y / (2 * alpha)
        F = (u > lb) & (u < ub)
        CF = C[:, F]
        H = CF @ CF.T / (2 * alpha) + 0.5 * np.eye(k)
        step = np.linalg.solve(H, grad)
        t = 1.0
        for _ls in range(40):
            yn = y + t * step
            zn = zf(yn)
            gn = dual(yn, zn)
            if gn >= gval + 1e-4 * t * (grad @ step) or _ls == 39:
                break
            t *= 0.5
        y, z, gval = yn, zn, gn
    A = np.vstack([np.sqrt(alpha) * np.eye(len(a)), C])
    b = np.r_[-np.sqrt(alpha) * a, d]
    return np.clip(lsq_linear(A, b, bounds=(lb, ub), method="bvls", tol=1e-13).x, lb, ub)
