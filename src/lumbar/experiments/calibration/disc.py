"""The disc law of paper 1 (Eq. 3) and its fit (calibration step 1), its inverse (the derived disc-only rows), and the
form of Eq. 7 that is zero at zero strain (the calibrated ligament laws).

Disc (step 1): the disc-only unit is in equilibrium where the disc torque equals the applied moment,
so Eq. 3 is fitted to the points (phi = measured mean ROM, T = M) by ``least_squares(method="trf")``;
start values from a grid over p2 with p1, p3 solved linearly (variable projection), then refined.
Lateral bending and axial rotation are symmetric (one law each), flexion and extension separate.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..stepwise_reduction import MAIN_DIRECTIONS

#: the stage the disc law is fitted on (the ligament-free unit)
DISC_STAGE = "wo_all"


def c_zero(a, b, d):
    """c of Eq. 7 such that F(0 %) = 0."""
    return -a * float(np.logaddexp(0.0, b / d))


def softplus_zero_law(eps_pct, a, b, d):
    """Eq. 7 with c = c_zero(a, b, d) (raw law, no tension-only rule) [N]."""
    return a * (np.logaddexp(0.0, (np.asarray(eps_pct, float) + b) / d) - np.logaddexp(0.0, b / d))


def eq3(phi_rad, p):
    p1, p2, p3 = p
    return p1 * np.tanh(np.asarray(phi_rad) ** 3 / p2) + p3 * np.asarray(phi_rad)


#: smallest p1 [N*m] of Eq. 3 a disc fit may take: the tanh term is the law's stiffening term (the paper's Table 1
#: has p1 > 0 in every direction); a negative p1 makes a law that is stiffest at zero and softens with the load, the
#: opposite of a disc (measured: a table with a neutral-zone laxity drove the free fit of flexion to p1 = -7.6 N*m,
#: p3 = +58 N*m/rad). At the bound (flagged ``at_bound``) the rows show no stiffening and the law is linear.
P1_MIN_NM = 0.0
#: largest p1 [N*m] of a disc fit: the characteristic tables' physical range (100 N*m, lumbar.inputs.characteristics)
#: divided by the largest torque scale of the admissible fit (4, calibration.admissible.DISC_TORQUE_SCALE_BOUNDS), so
#: that every law the calibration writes passes its own loader; 2.3 x the paper's largest p1 (10.67 N*m, Table 1). Rows
#: with a neutral-zone laxity can drive a free fit there (a step flagged at_bound)
P1_MAX_NM = 25.0


def fit_disc_direction(phi_rad, torque_nm):
    """Eq. 3 parameters (p1 [N*m], p2 [rad^3], p3 [N*m/rad]) with T(phi) = torque, least squares (trf) with
    p1 >= :data:`P1_MIN_NM` (p3 is free: the paper's flexion law has p3 < 0)."""
    from scipy.optimize import least_squares  # noqa: PLC0415 - scipy.optimize (about a second) only where a fit runs
    phi = np.asarray(phi_rad, float)
    M = np.asarray(torque_nm, float)
    ok = np.isfinite(phi) & np.isfinite(M)
    phi, M = phi[ok], M[ok]
    if phi.size < 3:
        raise ValueError(f"disc fit needs >= 3 finite (ROM, moment) points, got {phi.size}")
    best = None
    for lp2 in np.linspace(-8, 0, 81):          # variable projection start: p1, p3 linear for fixed p2
        p2 = 10.0 ** lp2
        A = np.column_stack([np.tanh(phi**3 / p2), phi])
        (p1, p3), *_ = np.linalg.lstsq(A, M, rcond=None)
        if p1 < P1_MIN_NM:                      # the linear law alone, p1 at its bound
            p1 = P1_MIN_NM
            p3 = float(np.linalg.lstsq(A[:, 1:], M - p1 * A[:, 0], rcond=None)[0][0])
        r = float(np.sum((A @ [p1, p3] - M) ** 2))
        if best is None or r < best[0]:
            best = (r, (p1, p2, p3))
    p0 = np.array(best[1])

    def res(q):
        return eq3(phi, (q[0], 10.0 ** q[1], q[2])) - M

    # the variable-projection start is unconstrained in p3 (and p1 above): start inside the fit's bounds
    x0 = np.clip([p0[0], math.log10(p0[1]), p0[2]], [P1_MIN_NM, -9.0, -1e3], [P1_MAX_NM, 1.0, 1e3])
    sol = least_squares(res, x0, method="trf",
                        bounds=([P1_MIN_NM, -9, -1e3], [P1_MAX_NM, 1, 1e3]), x_scale=[1.0, 0.1, 1.0],
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000)
    return float(sol.x[0]), float(10.0 ** sol.x[1]), float(sol.x[2])


def invert_eq3(p, moment_nm):
    """Smallest phi >= 0 [rad] with Eq. 3 T(phi) = moment (before any torque peak); NaN if none."""
    from scipy.optimize import brentq  # noqa: PLC0415 - scipy.optimize (about a second) only where a fit runs

    grid = np.linspace(0.0, math.radians(60.0), 60001)
    T = eq3(grid, p)
    above = np.flatnonzero(T >= moment_nm)
    if above.size == 0:
        return float("nan")
    j = above[0]
    if j == 0:
        return 0.0
    return brentq(lambda x: eq3(x, p) - moment_nm, grid[j - 1], grid[j], xtol=1e-14)


def derived_disc_only_rows(torque: dict, moments_nm=(1.0, 2.5, 5.0, 7.5, 10.0), source="", note="") -> pd.DataFrame:
    rows = []
    for d in MAIN_DIRECTIONS:
        for M in moments_nm:
            rows.append({"stage": DISC_STAGE, "direction": d, "moment_nm": float(M),
                         "rom_mean_deg": round(math.degrees(invert_eq3(torque[d], M)), 4),
                         "rom_min_deg": np.nan, "rom_max_deg": np.nan, "n_specimens": 8,
                         "kind": "derived_from_published_fit", "source": source, "note": note})
    return pd.DataFrame(rows)

