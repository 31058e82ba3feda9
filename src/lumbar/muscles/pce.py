"""Variance-based (Sobol) sensitivity indices from a Legendre polynomial chaos expansion (PCE).

The standard surrogate route (Sudret 2008, "Global sensitivity analysis using polynomial chaos expansions",
Reliab Eng Syst Saf 93:964-979): inputs independent and uniform, mapped to u in [-1, 1]; the model output is
expanded in the orthonormal Legendre polynomials of total degree <= p,

    y(u) ~ sum_a c_a psi_a(u),   psi_a(u) = prod_i sqrt(2 a_i + 1) P_{a_i}(u_i),

fitted by ordinary least squares on a training design (scrambled Sobol QMC points). Orthonormality makes the
variance decomposition analytic: D = sum_{a != 0} c_a^2, first-order S1_i = (sum of c_a^2 over the terms that
depend on u_i only) / D, total ST_i = (sum over the terms that involve u_i) / D. The accuracy of the fit is the
leave-one-out (LOO) coefficient of determination Q2_loo = 1 - mean((e_i / (1 - h_i))^2) / var(y), with e_i the
residuals and h_i the diagonal of the hat matrix (exact LOO for least squares, no refits). Sampling uncertainty
of the indices: bootstrap (resample the training rows with replacement, refit, recompute; percentile interval).

Everything here is dimensionless on u; :func:`to_unit` maps physical inputs (their own units) to u.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import legendre
from scipy.stats import qmc


def qmc_points(n: int, dim: int, seed: int) -> np.ndarray:
    """``n`` scrambled Sobol points in the unit cube [0, 1)^dim (scipy.stats.qmc.Sobol, Owen scrambling seeded
    by ``seed``). ``n`` must be a power of two (the balance properties of the sequence)."""
    n = int(n)
    if n < 1 or n & (n - 1):
        raise ValueError(f"number of Sobol points must be a power of two >= 1, got {n}")
    return qmc.Sobol(int(dim), scramble=True, rng=np.random.default_rng(seed)).random_base2(n.bit_length() - 1)


def to_unit(X, bounds) -> np.ndarray:
    """Map inputs uniform on ``bounds`` (rows (lower, upper), the inputs' units) to u in [-1, 1]."""
    X = np.atleast_2d(np.asarray(X, float))
    b = np.asarray(bounds, float)
    if b.shape != (X.shape[1], 2) or np.any(b[:, 1] <= b[:, 0]):
        raise ValueError(f"bounds must be {X.shape[1]} rows (lower < upper), got {b.tolist()}")
    return 2.0 * (X - b[:, 0]) / (b[:, 1] - b[:, 0]) - 1.0


def multi_indices(dim: int, degree: int) -> np.ndarray:
    """All multi-indices a in N^dim with |a| <= degree, rows ordered by total degree (row 0 = constant term).
    Their number is binom(dim + degree, degree)."""
    if dim < 1 or degree < 0:
        raise ValueError(f"need dim >= 1 and degree >= 0, got {dim}, {degree}")

    def rec(d, p):                      # all a in N^d with |a| == p
        if d == 1:
            return [(p,)]
        return [(k,) + rest for k in range(p, -1, -1) for rest in rec(d - 1, p - k)]

    return np.array([a for p in range(degree + 1) for a in rec(dim, p)], dtype=int)


def legendre_basis(U, alphas) -> np.ndarray:
    """Design matrix psi_a(u) (rows: points, columns: multi-indices) of the orthonormal Legendre basis
    (orthonormal for u uniform on [-1, 1]: E[psi_a psi_b] = delta_ab)."""
    U = np.atleast_2d(np.asarray(U, float))
    alphas = np.asarray(alphas, int)
    pmax = int(alphas.max()) if alphas.size else 0
    # one-dimensional values sqrt(2k+1) P_k(u), shape (n, dim, pmax + 1)
    V = np.stack([np.sqrt(2 * k + 1) * legendre.legval(U, np.eye(pmax + 1)[k]) for k in range(pmax + 1)], axis=-1)
    out = np.ones((U.shape[0], len(alphas)))
    for i in range(U.shape[1]):
        out *= V[:, i, alphas[:, i]]
    return out


def sobol_from_coefficients(coef, alphas):
    """First-order and total Sobol indices and the variance from the PCE coefficients (orthonormal basis).
    Returns (S1, ST, variance); NaN indices if the variance is zero."""
    coef, alphas = np.asarray(coef, float), np.asarray(alphas, int)
    c2 = coef ** 2
    nonconst = alphas.sum(axis=1) > 0
    var = float(c2[nonconst].sum())
    involved = alphas > 0                                          # (P, dim)
    only = involved & (involved.sum(axis=1) == 1)[:, None]
    if var <= 0.0:
        nan = np.full(alphas.shape[1], np.nan)
        return nan, nan.copy(), var
    return c2 @ only / var, c2 @ involved / var, var


@dataclass
class PCEFit:
    alphas: np.ndarray      # (P, dim) multi-indices
    coef: np.ndarray        # (P,) coefficients (units of y)
    degree: int
    n: int                  # training points
    q2_loo: float           # leave-one-out Q2 (1 = perfect; NaN if undefined: n <= P or constant y)
    S1: np.ndarray
    ST: np.ndarray
    variance: float         # model variance (units of y squared)

    @property
    def mean(self) -> float:
        return float(self.coef[0])

    def predict(self, U) -> np.ndarray:
        return legendre_basis(U, self.alphas) @ self.coef


def fit(U, y, degree: int) -> PCEFit:
    """Least-squares Legendre PCE of total degree ``degree`` on the points ``U`` (in [-1, 1]) and outputs ``y``,
    with the exact leave-one-out Q2 from the hat matrix and the analytic Sobol indices."""
    U = np.atleast_2d(np.asarray(U, float))
    y = np.asarray(y, float)
    if len(y) != len(U) or not np.all(np.isfinite(y)) or not np.all(np.isfinite(U)):
        raise ValueError("PCE fit: U and y must have the same finite rows")
    alphas = multi_indices(U.shape[1], int(degree))
    A = legendre_basis(U, alphas)
    coef = np.linalg.lstsq(A, y, rcond=None)[0]
    q2 = np.nan
    if len(y) > len(alphas) and np.var(y) > 0:
        Q, _ = np.linalg.qr(A)
        h = np.sum(Q ** 2, axis=1)
        if np.all(h < 1 - 1e-10):
            e = (y - A @ coef) / (1 - h)
            q2 = float(1 - np.mean(e ** 2) / np.var(y))
    S1, ST, var = sobol_from_coefficients(coef, alphas)
    return PCEFit(alphas, coef, int(degree), len(y), q2, S1, ST, var)


def bootstrap(U, y, degree: int, n_bootstrap: int, seed: int):
    """Bootstrap replicates of (S1, ST): ``n_bootstrap`` resamples of the training rows with replacement, each
    refitted (least squares, minimum-norm if a resample is rank deficient). Returns two arrays
    (n_bootstrap, dim)."""
    U = np.atleast_2d(np.asarray(U, float))
    y = np.asarray(y, float)
    alphas = multi_indices(U.shape[1], int(degree))
    A = legendre_basis(U, alphas)
    rng = np.random.default_rng(seed)
    S1 = np.empty((int(n_bootstrap), U.shape[1]))
    ST = np.empty_like(S1)
    for b in range(int(n_bootstrap)):
        idx = rng.integers(0, len(y), len(y))
        w = np.bincount(idx, minlength=len(y)).astype(float)     # a resample = integer weights on the rows
        try:                                                       # normal equations, Cholesky (fast)
            if np.count_nonzero(w) < len(alphas):
                raise np.linalg.LinAlgError("fewer distinct rows than terms")
            L = np.linalg.cholesky((A * w[:, None]).T @ A)
            if np.min(np.diag(L)) ** 2 < 1e-10 * np.max(np.diag(L)) ** 2:
                raise np.linalg.LinAlgError("ill-conditioned")
            c = np.linalg.solve(L.T, np.linalg.solve(L, A.T @ (w * y)))
        except np.linalg.LinAlgError:
            c = np.linalg.lstsq(A[idx], y[idx], rcond=None)[0]
        S1[b], ST[b], _ = sobol_from_coefficients(c, alphas)
    return S1, ST


def sobol_analysis(U, y, degree: int, n_bootstrap: int = 500, seed: int = 0, level: float = 0.95) -> dict:
    """PCE fit and Sobol indices with bootstrap percentile intervals at ``level``: a dict of the fit
    (:class:`PCEFit`) and arrays S1, S1_lo, S1_hi, ST, ST_lo, ST_hi (one entry per input)."""
    f = fit(U, y, degree)
    q = 100 * np.array([(1 - level) / 2, (1 + level) / 2])
    out = {"fit": f, "S1": f.S1, "ST": f.ST}
    if n_bootstrap > 0:
        b1, bt = bootstrap(U, y, degree, n_bootstrap, seed)
        (out["S1_lo"], out["S1_hi"]), (out["ST_lo"], out["ST_hi"]) = (np.nanpercentile(b1, q, axis=0),
                                                                      np.nanpercentile(bt, q, axis=0))
    else:
        for k in ("S1_lo", "S1_hi", "ST_lo", "ST_hi"):
            out[k] = np.full(U.shape[1], np.nan)
    return out
