"""Millard et al. (2013) normalised muscle curves, built as in OpenSim's SmoothSegmentedFunctionFactory.

Each curve is a chain of quintic Bezier "corner" segments (SegmentedQuinticBezierToolkit::
calcQuinticBezierCornerControlPoints: control points x0, x0+c(xC-x0) (twice), x1+c(xC-x1) (twice), x1,
with xC the intersection of the two end tangents and c = 0.1 + 0.8*curviness), extrapolated linearly
outside its domain with the end slopes. Values and first derivatives are analytic: x(u), y(u) are
quintic polynomials, u is found from x by safeguarded Newton, and dy/dx = y'(u)/x'(u).

Curves and their parameters (OpenSim 4.6 defaults; tests/test_muscles.py checks every curve against values
evaluated by OpenSim 4.6 itself, tests/data/opensim_millard_curves.csv, to ~1e-13):
* active force-length (ActiveForceLengthCurve): min_norm_active_fiber_length 0.47-0.0259 = 0.4441,
  transition_norm_fiber_length 0.73, optimum 1, max_norm_active_fiber_length 1.8123, shallow ascending slope
  0.8616, minimum value 0.1, curviness 1 (shoulder half-width 0.05, ascending-limb mid slope 1.25 y1/(x1-x0)).
  (Until 2026-11: transition 0.6259, shoulder 0.0259 and mid slope y1/(x1-x0-0.0259), the older
  construction, up to 0.13 off OpenSim 4.6: 0.579 vs 0.451 at lce 0.6, 0.902 vs 0.957 at 1.1.)
* passive (fibre) force-length (FiberForceLengthCurve / createFiberForceLengthCurve, OpenSim 4 defaults):
  zero below strain e0 = 0, a toe segment to strain min(0.1/kiso, 0.1 e1) = 0.035 with stiffness at low
  force klow = 0.2, then 1 at strain e1 = 0.7 with stiffness kiso = 2/0.7, curviness 0.75. Tangent moduli
  with K = 1 MPa: 0.23, 1.07, 2.30, 2.86 MPa at 10, 30, 50, 70 % strain, beside the paper's baseline
  0.26, 1.01, 2.45, 2.86 (Sect. 2.5; checked in the tests). (Until 2026-11-23 the toe segment was missing:
  a single corner from (1, 0, slope 0) gave 0.08 MPa at 10 % strain and 3-30x less force below 10 %.)
* force-velocity (ForceVelocityCurve, for completeness; the static model does not use it): fmaxE 1.4,
  slopes 0 at -vmax, 0.25 near -vmax (-0.9), 5 at isometric, 0.15 near +vmax (0.9), 0 at +vmax, curviness
  0.6 (concentric) / 0.9 (eccentric). (Until 2026-11 without the near-vmax points, up to 0.09 off.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mechanics import kernel
from . import compiled

_B = np.array([[-1, 5, -10, 10, -5, 1],      # quintic Bernstein basis, rows = powers u^5 .. u^0
               [5, -20, 30, -20, 5, 0],
               [-10, 30, -30, 10, 0, 0],
               [10, -20, 10, 0, 0, 0],
               [-5, 5, 0, 0, 0, 0],
               [1, 0, 0, 0, 0, 0]], float)


def corner_control_points(x0, y0, dydx0, x1, y1, dydx1, curviness):
    """Six x and six y control points of one C-shaped quintic Bezier corner (OpenSim's rule)."""
    if not 0.0 <= curviness <= 1.0:
        raise ValueError(f"curviness must be in [0, 1], got {curviness}")
    c = 0.1 + 0.8 * curviness
    if abs(dydx0 - dydx1) > np.sqrt(np.finfo(float).eps):
        xc = (y1 - y0 - x1 * dydx1 + x0 * dydx0) / (dydx0 - dydx1)
    else:
        xc = 0.5 * (x0 + x1)
    yc = (xc - x1) * dydx1 + y1
    a = (xc - x0) ** 2 + (yc - y0) ** 2
    b = (xc - x1) ** 2 + (yc - y1) ** 2
    d = (x1 - x0) ** 2 + (y1 - y0) ** 2
    if not (d > a and d > b):
        raise ValueError("corner end points and slopes do not form a C-shaped corner")
    x0m, y0m = x0 + c * (xc - x0), y0 + c * (yc - y0)
    x1m, y1m = x1 + c * (xc - x1), y1 + c * (yc - y1)
    return np.array([x0, x0m, x0m, x1m, x1m, x1]), np.array([y0, y0m, y0m, y1m, y1m, y1])


@dataclass
class SmoothSegmentedCurve:
    """Piecewise quintic Bezier curve y(x) with linear extrapolation; ``value_and_slope`` is vectorised."""

    name: str
    px: np.ndarray      # (nseg, 6)
    py: np.ndarray      # (nseg, 6)
    ends: tuple | None = None   # (y_lo, y_hi, slope_lo, slope_hi) of the linear extrapolation, as OpenSim's

    def __post_init__(self):
        self.px = np.atleast_2d(np.asarray(self.px, float))
        self.py = np.atleast_2d(np.asarray(self.py, float))
        self.cx = self.px @ _B.T          # polynomial coefficients, powers u^5..u^0
        self.cy = self.py @ _B.T
        self.x_lo, self.x_hi = self.px[0, 0], self.px[-1, -1]
        self._x_table = np.stack([np.polyval(c, _U_TABLE) for c in self.cx])   # x(u) per segment (monotone)
        self._starts = np.ascontiguousarray(self.px[:, 0])
        if self.ends is None:
            self.y_lo, self.y_hi = self.py[0, 0], self.py[-1, -1]
            self.s_lo = self._slope_end(0, 0.0)
            self.s_hi = self._slope_end(-1, 1.0)
        else:
            self.y_lo, self.y_hi, self.s_lo, self.s_hi = map(float, self.ends)

    def _slope_end(self, seg, u):
        dx = np.polyval(np.polyder(self.cx[seg]), u)
        dy = np.polyval(np.polyder(self.cy[seg]), u)
        return dy / dx

    def value_and_slope(self, x):
        """y(x) and dy/dx(x) for an array of x: compiled (:mod:`lumbar.muscles.compiled`) when the solver kernel
        is active, else :meth:`value_and_slope_reference`."""
        if not kernel.active():
            return self.value_and_slope_reference(x)
        x = np.asarray(x, float)
        flat = np.ascontiguousarray(x.reshape(-1))
        y, dydx = np.empty_like(flat), np.empty_like(flat)
        compiled.curve_values(flat, self._starts, self.cx, self.cy, self._x_table, _U_TABLE, float(self.x_lo),
                              float(self.x_hi), float(self.y_lo), float(self.y_hi), float(self.s_lo),
                              float(self.s_hi), y, dydx)
        return y.reshape(x.shape), dydx.reshape(x.shape)

    def value_and_slope_reference(self, x):
        """The numpy reference of :meth:`value_and_slope`."""
        x = np.asarray(x, float)
        flat = x.reshape(-1)
        y = np.empty_like(flat)
        dydx = np.empty_like(flat)
        lo, hi = flat <= self.x_lo, flat >= self.x_hi
        y[lo] = self.y_lo + self.s_lo * (flat[lo] - self.x_lo)
        dydx[lo] = self.s_lo
        y[hi] = self.y_hi + self.s_hi * (flat[hi] - self.x_hi)
        dydx[hi] = self.s_hi
        mid = ~(lo | hi)
        if mid.any():
            xm = flat[mid]
            starts = self.px[:, 0]
            seg = np.clip(np.searchsorted(starts, xm, side="right") - 1, 0, len(starts) - 1)
            cx, cy = self.cx[seg], self.cy[seg]
            # start: bracket and linear interpolation in a table of x(u) at 65 u per segment (Newton alone from
            # u = 1/2 fell back to bisection near the segment ends, where dx/du vanishes: up to 30 sweeps)
            xg = self._x_table
            k = np.empty(xm.shape, int)
            for sg in range(len(xg)):
                on = seg == sg
                k[on] = np.clip(np.searchsorted(xg[sg], xm[on], side="right") - 1, 0, xg.shape[1] - 2)
            a, b = _U_TABLE[k], _U_TABLE[k + 1]
            xa, xb = xg[seg, k], xg[seg, k + 1]
            u = a + (b - a) * np.clip((xm - xa) / np.where(xb > xa, xb - xa, 1.0), 0.0, 1.0)
            # safeguarded Newton on x(u) = x (x(u) monotone): a Newton step that leaves the bracket [a, b] is
            # replaced by bisection. Converged when every point's step is at round-off or its residual x(u) - x
            # is at the round-off of x(u): a step landing on a bracket end is kept (treating it as leaving the bracket
            # threw converged points back to a bisection midpoint), and a point oscillating between two floats
            # stops there (both took every call to all 60 iterations, 5-10x the work of converging).
            # (round-off of x(u) scales with the polynomial's coefficients, not with x: x ~ 0 on force-velocity)
            tol = 4.0 * np.finfo(float).eps * np.maximum(1.0, np.abs(cx).sum(1))
            for _ in range(60):
                f = _poly(cx, u) - xm
                a = np.where(f < 0, u, a)
                b = np.where(f >= 0, u, b)
                d = _dpoly(cx, u)
                un = u - f / np.where(np.abs(d) > 1e-300, d, 1e-300)
                bad = (un < a) | (un > b) | ~np.isfinite(un)
                un = np.where(bad, 0.5 * (a + b), un)
                if np.all((np.abs(un - u) <= 4e-16) | (np.abs(f) <= tol)):
                    u = np.where(np.abs(f) <= tol, u, un)
                    break
                u = un
            y[mid] = _poly(cy, u)
            dydx[mid] = _dpoly(cy, u) / _dpoly(cx, u)
        return y.reshape(x.shape), dydx.reshape(x.shape)

    def __call__(self, x):
        return self.value_and_slope(x)[0]


_U_TABLE = np.linspace(0.0, 1.0, 65)


def _poly(c, u):
    out = c[:, 0].copy()
    for k in range(1, 6):
        out = out * u + c[:, k]
    return out


def _dpoly(c, u):
    out = 5 * c[:, 0]
    for k in range(1, 5):
        out = out * u + (5 - k) * c[:, k]
    return out


def active_force_length_curve(x0=0.47 - 0.0259, x1=0.73, x2=1.0, x3=1.8123, ylow=0.1, dydx=0.8616,
                              curviness=1.0) -> SmoothSegmentedCurve:
    """Normalised active force-length curve, OpenSim 4.6 ``ActiveForceLengthCurve()`` defaults.

    ``x0`` min_norm_active_fiber_length, ``x1`` transition_norm_fiber_length, ``x2`` optimal length (1),
    ``x3`` max_norm_active_fiber_length, ``ylow`` minimum_value, ``dydx`` shallow_ascending_slope; five
    corner segments joined at (Millard 2013 / createFiberActiveForceLengthCurve, OpenSim 4):

    * ascending limb midpoint ``x01 = (x0+x1)/2``, ``y01 = y1/2`` with slope ``1.25 y1/(x1-x0)``, where
      ``y1 = 1 - dydx (xs - x1)`` and the shoulder ``xs = x2 - 0.05 x2``;
    * shallow plateau midpoint ``x1s = (x1+xs)/2``, ``y1s = (1+y1)/2`` with slope ``dydx``;
    * plateau (x2, 1, slope 0);
    * descending limb midpoint ``x23 = (1.05 x2 + x3)/2``, ``y23 = 1/2`` with slope ``-1/(x3 - 1.1 x2)``;
    * both ends at ``ylow`` with zero slope (and constant ``ylow`` outside [x0, x3]).
    """
    root_eps = np.sqrt(np.finfo(float).eps)
    if not (x0 >= 0 and x1 > x0 + root_eps and x2 > x1 + root_eps and x3 > x2 + root_eps):
        raise ValueError("need 0 <= lce0 < lce1 < lce2 < lce3")
    if not ylow >= 0:
        raise ValueError(f"minimum value must be >= 0, got {ylow}")
    if not 0 <= dydx < (1 - ylow) / (x2 - x1):
        raise ValueError("shallow ascending slope out of range [0, (1-ylow)/(lce2-lce1))")
    xd = 0.05 * x2
    xs = x2 - xd
    y0 = 0.0
    y1 = 1 - dydx * (xs - x1)
    dydx01 = 1.25 * (y1 - y0) / (x1 - x0)
    x01, y01 = x0 + 0.5 * (x1 - x0), y0 + 0.5 * (y1 - y0)
    x1s, y1s = x1 + 0.5 * (xs - x1), y1 + 0.5 * (1 - y1)
    y2, dydx2, y3, dydx3 = 1.0, 0.0, 0.0, 0.0
    x23 = (x2 + xd) + 0.5 * (x3 - (x2 + xd))
    y23 = y2 + 0.5 * (y3 - y2)
    dydx23 = (y3 - y2) / ((x3 - xd) - (x2 + xd))
    segs = [(x0, ylow, 0.0, x01, y01, dydx01), (x01, y01, dydx01, x1s, y1s, dydx),
            (x1s, y1s, dydx, x2, y2, dydx2), (x2, y2, dydx2, x23, y23, dydx23),
            (x23, y23, dydx23, x3, ylow, dydx3)]
    pts = [corner_control_points(*s, curviness) for s in segs]
    return SmoothSegmentedCurve("active_force_length", [p[0] for p in pts], [p[1] for p in pts],
                                ends=(ylow, ylow, 0.0, 0.0))


def passive_force_length_curve(e0=0.0, e1=0.7, klow=0.2, kiso=2.0 / 0.7, curviness=0.75) -> SmoothSegmentedCurve:
    """Normalised passive fibre force-length curve (createFiberForceLengthCurve); x = 1 + strain.

    Two corner segments as in OpenSim 4: (1+e0, 0, slope 0) -> (xlow, ylow, slope klow) -> (1+e1, 1, kiso)
    with ``xlow = 1+e0 + dx``, ``dx = min(0.1/kiso, 0.1 (e1-e0))``, ``ylow = klow dx / 2`` (the toe)."""
    if not e1 > e0:
        raise ValueError("strain at one normalised force must exceed the strain at zero force")
    if not kiso > 1.0 / (e1 - e0):
        raise ValueError(f"stiffness at one normalised force must exceed 1/(e1-e0) = {1 / (e1 - e0):.4g}")
    if not 0.0 < klow < 1.0 / (e1 - e0):
        raise ValueError(f"stiffness at low force (klow) must be in (0, 1/(e1-e0) = {1 / (e1 - e0):.4g})")
    x0, xiso = 1.0 + e0, 1.0 + e1
    dx = min(0.1 / kiso, 0.1 * (xiso - x0))
    xlow, ylow = x0 + dx, klow * 0.5 * dx
    p0 = corner_control_points(x0, 0.0, 0.0, xlow, ylow, klow, curviness)
    p1 = corner_control_points(xlow, ylow, klow, xiso, 1.0, kiso, curviness)
    return SmoothSegmentedCurve("passive_force_length", [p0[0], p1[0]], [p0[1], p1[1]], ends=(0.0, 1.0, 0.0, kiso))


def force_velocity_curve(fmax_e=1.4, dydx_c=0.0, dydx_near_c=0.25, dydx_iso=5.0, dydx_e=0.0, dydx_near_e=0.15,
                         curv_c=0.6, curv_e=0.9) -> SmoothSegmentedCurve:
    """Normalised force-velocity curve, OpenSim 4.6 ``ForceVelocityCurve()`` defaults; x = v / vmax in [-1, 1].

    Four corner segments (createFiberForceVelocityCurve): (-1, 0, dydx_c) -> (-0.9, y_nc, dydx_near_c) ->
    (0, 1, dydx_iso) -> (0.9, y_ne, dydx_near_e) -> (1, fmax_e, dydx_e), with the near-vmax values from the
    mean of the two slopes, ``y_nc = 0.1 (dydx_near_c + dydx_c)/2`` and ``y_ne = fmax_e - 0.1 (dydx_near_e +
    dydx_e)/2``; linear outside [-1, 1] with the end slopes. (The static model does not use it.)"""
    if not fmax_e > 1:
        raise ValueError(f"fmax_e must be > 1, got {fmax_e}")
    if not (0 <= dydx_c < 1 and dydx_c < dydx_near_c <= 1):
        raise ValueError("need 0 <= dydx_c < dydx_near_c <= 1")
    if not dydx_iso > 1:
        raise ValueError(f"dydx_iso must be > 1, got {dydx_iso}")
    if not (0 <= dydx_e < fmax_e - 1 and dydx_e <= dydx_near_e < fmax_e - 1):
        raise ValueError("need 0 <= dydx_e <= dydx_near_e < fmax_e - 1")
    xnc, xne = -0.9, 0.9
    ync = 0.5 * dydx_near_c * (xnc + 1) + 0.5 * dydx_c * (xnc + 1)
    yne = fmax_e + 0.5 * dydx_near_e * (xne - 1) + 0.5 * dydx_e * (xne - 1)
    segs = [(-1.0, 0.0, dydx_c, xnc, ync, dydx_near_c, curv_c), (xnc, ync, dydx_near_c, 0.0, 1.0, dydx_iso, curv_c),
            (0.0, 1.0, dydx_iso, xne, yne, dydx_near_e, curv_e), (xne, yne, dydx_near_e, 1.0, fmax_e, dydx_e, curv_e)]
    pts = [corner_control_points(*s) for s in segs]
    return SmoothSegmentedCurve("force_velocity", [p[0] for p in pts], [p[1] for p in pts],
                                ends=(0.0, fmax_e, dydx_c, dydx_e))


ACTIVE_FL = active_force_length_curve()
PASSIVE_FL = passive_force_length_curve()
FORCE_VELOCITY = force_velocity_curve()
