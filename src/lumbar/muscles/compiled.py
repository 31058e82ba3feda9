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

from ..mechanics.kernel import inner_jit as _inner
from ..mechanics.kernel import jit as _jit


@_inner
def _end(x, R, c, body, s, bi):
    """World position p and lever arm r = R (s - c) of a path point ``s`` on ``body`` (< 0: fixed, s in world
    coordinates, r = 0) in scenario ``bi``."""
    if body < 0:
        return s[0], s[1], s[2], 0.0, 0.0, 0.0
    d0, d1, d2 = s[0] - c[body, 0], s[1] - c[body, 1], s[2] - c[body, 2]
    r0 = R[bi, body, 0, 0] * d0 + R[bi, body, 0, 1] * d1 + R[bi, body, 0, 2] * d2
    r1 = R[bi, body, 1, 0] * d0 + R[bi, body, 1, 1] * d1 + R[bi, body, 1, 2] * d2
    r2 = R[bi, body, 2, 0] * d0 + R[bi, body, 2, 1] * d1 + R[bi, body, 2, 2] * d2
    return x[bi, body, 0] + r0, x[bi, body, 1] + r1, x[bi, body, 2] + r2, r0, r1, r2


@_inner
def _add_gradient(G, bi, m, body, sign, u0, u1, u2, r0, r1, r2):
    """G[bi, m, body] += sign (u, r x u): a path end's share of dL/d(x, w)."""
    if body < 0:
        return
    G[bi, m, body, 0] += sign * u0
    G[bi, m, body, 1] += sign * u1
    G[bi, m, body, 2] += sign * u2
    G[bi, m, body, 3] += sign * (r1 * u2 - r2 * u1)
    G[bi, m, body, 4] += sign * (r2 * u0 - r0 * u2)
    G[bi, m, body, 5] += sign * (r0 * u1 - r1 * u0)


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
        for k in range(seg_m.shape[0]):
            m = seg_m[k]
            pa0, pa1, pa2, ra0, ra1, ra2 = _end(x, R, c, seg_a[k], sa[k], bi)
            pb0, pb1, pb2, rb0, rb1, rb2 = _end(x, R, c, seg_b[k], sb[k], bi)
            e0, e1, e2 = pa0 - pb0, pa1 - pb1, pa2 - pb2
            ln = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            L[bi, m] += ln
            if gradient:
                u0, u1, u2 = e0 / ln, e1 / ln, e2 / ln
                _add_gradient(G, bi, m, seg_a[k], 1.0, u0, u1, u2, ra0, ra1, ra2)
                _add_gradient(G, bi, m, seg_b[k], -1.0, u0, u1, u2, rb0, rb1, rb2)


@_inner
def _poly(c, seg, u):
    out = c[seg, 0]
    for k in range(1, 6):
        out = out * u + c[seg, k]
    return out


@_inner
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
