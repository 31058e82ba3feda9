"""Compiled (numba) forms of the muscle model's two per-scenario hot spots: the muscle path lengths with their
derivative (:meth:`lumbar.muscles.paths.MusclePaths.lengths`) and the Millard curves
(:meth:`lumbar.muscles.millard.SmoothSegmentedCurve.value_and_slope`).

Both compute the same quantities with the same formulas as their numpy reference paths, point by point instead of
in small array operations (which spent most of the redundancy solver's time at its batch sizes); the switch is the
passive solver's (:mod:`lumbar.mechanics.kernel`: ``LUMBAR_KERNEL``, ``set_mode``, ``use``), so one switch selects
the reference path of the whole model. tests/test_muscles.py compares both paths to 1e-12.
"""
from __future__ import annotations

import numpy as np

from ..mechanics.kernel import jit as _jit


@_jit
def path_lengths(x, R, c, seg_m, seg_a, seg_b, sa, sb, const, gradient, L, G):
    """Fill L (B, nm) with the path lengths and, when ``gradient``, G (B, nm, nb, 6) (zeroed by the caller) with
    dL/dq: per segment between bodies a and b (index < 0: fixed, the point is in world coordinates) its length,
    its unit vector u and the lever arms r = R (s - c) of its ends: dL/d(x_a, w_a) = (u, r_a x u), minus that at b."""
    B = x.shape[0]
    nm = const.shape[0]
    for bi in range(B):
        for m in range(nm):
            L[bi, m] = const[m]
        for s in range(seg_m.shape[0]):
            ia, ib, m = seg_a[s], seg_b[s], seg_m[s]
            ra0 = ra1 = ra2 = rb0 = rb1 = rb2 = 0.0
            if ia >= 0:
                d0, d1, d2 = sa[s, 0] - c[ia, 0], sa[s, 1] - c[ia, 1], sa[s, 2] - c[ia, 2]
                ra0 = R[bi, ia, 0, 0] * d0 + R[bi, ia, 0, 1] * d1 + R[bi, ia, 0, 2] * d2
                ra1 = R[bi, ia, 1, 0] * d0 + R[bi, ia, 1, 1] * d1 + R[bi, ia, 1, 2] * d2
                ra2 = R[bi, ia, 2, 0] * d0 + R[bi, ia, 2, 1] * d1 + R[bi, ia, 2, 2] * d2
                pa0, pa1, pa2 = x[bi, ia, 0] + ra0, x[bi, ia, 1] + ra1, x[bi, ia, 2] + ra2
            else:
                pa0, pa1, pa2 = sa[s, 0], sa[s, 1], sa[s, 2]
            if ib >= 0:
                d0, d1, d2 = sb[s, 0] - c[ib, 0], sb[s, 1] - c[ib, 1], sb[s, 2] - c[ib, 2]
                rb0 = R[bi, ib, 0, 0] * d0 + R[bi, ib, 0, 1] * d1 + R[bi, ib, 0, 2] * d2
                rb1 = R[bi, ib, 1, 0] * d0 + R[bi, ib, 1, 1] * d1 + R[bi, ib, 1, 2] * d2
                rb2 = R[bi, ib, 2, 0] * d0 + R[bi, ib, 2, 1] * d1 + R[bi, ib, 2, 2] * d2
                pb0, pb1, pb2 = x[bi, ib, 0] + rb0, x[bi, ib, 1] + rb1, x[bi, ib, 2] + rb2
            else:
                pb0, pb1, pb2 = sb[s, 0], sb[s, 1], sb[s, 2]
            e0, e1, e2 = pa0 - pb0, pa1 - pb1, pa2 - pb2
            ln = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            L[bi, m] += ln
            if not gradient:
                continue
            u0, u1, u2 = e0 / ln, e1 / ln, e2 / ln
            if ia >= 0:
                G[bi, m, ia, 0] += u0
                G[bi, m, ia, 1] += u1
                G[bi, m, ia, 2] += u2
                G[bi, m, ia, 3] += ra1 * u2 - ra2 * u1
                G[bi, m, ia, 4] += ra2 * u0 - ra0 * u2
                G[bi, m, ia, 5] += ra0 * u1 - ra1 * u0
            if ib >= 0:
                G[bi, m, ib, 0] -= u0
                G[bi, m, ib, 1] -= u1
                G[bi, m, ib, 2] -= u2
                G[bi, m, ib, 3] -= rb1 * u2 - rb2 * u1
                G[bi, m, ib, 4] -= rb2 * u0 - rb0 * u2
                G[bi, m, ib, 5] -= rb0 * u1 - rb1 * u0


@_jit
def _poly(c, seg, u):
    out = c[seg, 0]
    for k in range(1, 6):
        out = out * u + c[seg, k]
    return out


@_jit
def _dpoly(c, seg, u):
    out = 5.0 * c[seg, 0]
    for k in range(1, 5):
        out = out * u + (5 - k) * c[seg, k]
    return out


@_jit
def curve_values(xs, starts, cx, cy, xtab, utab, x_lo, x_hi, y_lo, y_hi, s_lo, s_hi, y, dydx):
    """y(x) and dy/dx of a piecewise quintic Bezier curve for every x of ``xs`` (1-D), as the reference: linear
    extrapolation outside [x_lo, x_hi]; inside, the segment, a start bracketed in the table x(u) and a safeguarded
    Newton iteration on x(u) = x (a step leaving the bracket is replaced by bisection)."""
    nseg, nt = cx.shape[0], utab.shape[0]
    eps4 = 4.0 * np.finfo(np.float64).eps
    for i in range(xs.shape[0]):
        xv = xs[i]
        if xv <= x_lo:
            y[i] = y_lo + s_lo * (xv - x_lo)
            dydx[i] = s_lo
            continue
        if xv >= x_hi:
            y[i] = y_hi + s_hi * (xv - x_hi)
            dydx[i] = s_hi
            continue
        seg = min(max(np.searchsorted(starts, xv, side="right") - 1, 0), nseg - 1)
        k = min(max(np.searchsorted(xtab[seg], xv, side="right") - 1, 0), nt - 2)
        a, b = utab[k], utab[k + 1]
        xa, xb = xtab[seg, k], xtab[seg, k + 1]
        w = (xv - xa) / (xb - xa if xb > xa else 1.0)
        u = a + (b - a) * min(max(w, 0.0), 1.0)
        csum = 0.0
        for j in range(6):
            csum += abs(cx[seg, j])
        tol = eps4 * max(1.0, csum)
        for _ in range(60):
            f = _poly(cx, seg, u) - xv
            if f < 0:
                a = u
            else:
                b = u
            d = _dpoly(cx, seg, u)
            un = u - f / (d if abs(d) > 1e-300 else 1e-300)
            if un < a or un > b or not np.isfinite(un):
                un = 0.5 * (a + b)
            if abs(un - u) <= 4e-16 or abs(f) <= tol:
                if abs(f) > tol:
                    u = un
                break
            u = un
        y[i] = _poly(cy, seg, u)
        dydx[i] = _dpoly(cy, seg, u) / _dpoly(cx, seg, u)
