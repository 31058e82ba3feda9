"""Batched static equilibrium: Newton with line search, step limits and load continuation.

All scenarios of a batch advance together through the load steps ``lambda = k / n``; each
step is a damped Newton solve on the scenarios still alive. A scenario whose Newton solve
does not reach the tolerances within ``max_iter`` iterations is frozen at its last converged
load level and flagged ``converged = False`` (with its residual), never silently returned.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from . import so3

log = logging.getLogger(__name__)

LENGTH_SCALE = 0.05  # m, converts moments to forces in the merit function


@dataclass
class SolveResult:
    x: np.ndarray                 # (B, nb, 3)
    R: np.ndarray                 # (B, nb, 3, 3)
    converged: np.ndarray         # (B,) bool
    residual_force: np.ndarray    # (B,) max |force residual| [N]
    residual_moment: np.ndarray   # (B,) max |moment residual| [N*m]
    iterations: np.ndarray        # (B,) Newton iterations in total
    load_fraction: np.ndarray     # (B,) last load fraction reached with a converged solve

    def summary(self):
        n = len(self.converged)
        return (f"{int(self.converged.sum())}/{n} converged; max residual "
                f"{self.residual_force.max(initial=0):.2e} N, {self.residual_moment.max(initial=0):.2e} N*m")


def _take(a, idx, B):
    """Select scenarios ``idx`` from an array that is either per-scenario (leading B) or shared."""
    if a is None or np.ndim(a) == 0:
        return a
    a = np.asarray(a)
    return a[idx] if a.shape[0] == B and a.ndim >= 2 else a


def _take_params(params, idx, B):
    if not params:
        return params
    return {k: (np.asarray(v)[idx] if np.ndim(v) and np.shape(v)[0] == B else v) for k, v in params.items()}


def _residual_norms(Q):
    return np.abs(Q[..., :3]).max(axis=(-1, -2)), np.abs(Q[..., 3:]).max(axis=(-1, -2))


def _merit(Q):
    return (Q[..., :3] ** 2).sum(axis=(-1, -2)) + ((Q[..., 3:] / LENGTH_SCALE) ** 2).sum(axis=(-1, -2))


def _modified_newton_step(A, Q, nb):
    """Solve A d = Q; where the (scaled) symmetric part of the stiffness A is not positive
    definite, shift it (modified Newton) so the step does positive work along the load.

    Variables are scaled (rotations by LENGTH_SCALE) so translational and rotational
    stiffnesses are comparable before the eigenvalue test.
    """
    n = A.shape[-1]
    S = np.tile(np.r_[np.ones(3), np.full(3, 1.0 / LENGTH_SCALE)], nb)
    As = A * S[:, None] * S[None, :]
    sym = 0.5 * (As + np.swapaxes(As, -1, -2))
    lam = np.linalg.eigvalsh(sym)[:, 0]
    scale = np.abs(np.diagonal(sym, axis1=-2, axis2=-1)).max(-1)
    mu = np.where(lam < 1e-8 * scale, -lam + 1e-6 * scale, 0.0)
    As = As + mu[:, None, None] * np.eye(n)
    d = np.linalg.solve(As, (S * Q)[..., None])[..., 0] * S
    return d.reshape(-1, nb, 6)


def newton(model, x, R, loads, fmask=1.0, cmask=1.0, params=None, max_iter=50, tol_force=1e-8,
           tol_moment=1e-8, max_step_trans=1e-3, max_step_rot=0.05, damping=(1.0, 1e-6)):
    """Damped Newton on a batch; returns (x, R, converged, res_f, res_m, iterations)."""
    B, nb = x.shape[:2]
    n = 6 * nb
    x, R = x.copy(), R.copy()
    conv = np.zeros(B, bool)
    iters = np.zeros(B, int)
    res_f = np.full(B, np.inf)
    res_m = np.full(B, np.inf)
    reg = np.tile(np.r_[np.full(3, damping[0]), np.full(3, damping[1])], nb)
    active = np.arange(B)
    for _ in range(max_iter + 1):
        if active.size == 0:
            break
        xa, Ra = x[active], R[active]
        La = _take(loads, active, B)
        fm, cm, pa = _take(fmask, active, B), _take(cmask, active, B), _take_params(params, active, B)
        Q, J = model.evaluate(xa, Ra, La, fm, cm, jacobian=True, params=pa)
        rf, rm = _residual_norms(Q)
        res_f[active], res_m[active] = rf, rm
        done = (rf < tol_force) & (rm < tol_moment)
        conv[active[done]] = True
        keep = ~done
        if iters[active].max(initial=0) >= max_iter:
            break
        active, xa, Ra, Q, J = active[keep], xa[keep], Ra[keep], Q[keep], J[keep]
        if active.size == 0:
            break
        fm, cm, pa = _take(fmask, active, B), _take(cmask, active, B), _take_params(params, active, B)
        La = _take(loads, active, B)
        d = _modified_newton_step(-J.reshape(-1, n, n) + np.diag(reg), Q.reshape(-1, n), nb)
        # step limits per body
        st = np.linalg.norm(d[..., :3], axis=-1).max(-1) / max_step_trans
        sr = np.linalg.norm(d[..., 3:], axis=-1).max(-1) / max_step_rot
        d = d / np.maximum(1.0, np.maximum(st, sr))[:, None, None]
        m0 = _merit(Q)
        alpha = np.ones(active.size)
        accepted = np.zeros(active.size, bool)
        xn, Rn = xa.copy(), Ra.copy()
        for _ls in range(10):
            todo = ~accepted
            xt = xa + alpha[:, None, None] * d[..., :3]
            Rt = so3.exp(alpha[:, None, None] * d[..., 3:]) @ Ra
            Qt, _ = model.evaluate(xt, Rt, La, fm, cm, jacobian=False, params=pa)
            ok = todo & (_merit(Qt) < m0 * (1.0 - 1e-4 * alpha))
            xn[ok], Rn[ok] = xt[ok], Rt[ok]
            accepted |= ok
            if accepted.all():
                break
            alpha = np.where(accepted, alpha, alpha * 0.5)
        # where no decrease was found (a local minimum of the merit, e.g. at the torque minimum of
        # Eq. 3 with p3 < 0), take the full step-limited Newton step to hop over it
        if not accepted.all():
            nf = ~accepted
            xn[nf] = xa[nf] + d[nf][..., :3]
            Rn[nf] = so3.exp(d[nf][..., 3:]) @ Ra[nf]
        x[active], R[active] = xn, Rn
        iters[active] += 1
    return x, R, conv, res_f, res_m, iters


def solve(model, loads, x0=None, R0=None, fmask=1.0, cmask=1.0, params=None, load_steps=5,
          max_iter=50, tol_force=1e-8, tol_moment=1e-8, **kw) -> SolveResult:
    """Equilibrium under ``loads`` (B, nb, 6), reached by load continuation from the start state.

    The start state (default: reference configuration) is first brought to equilibrium under
    zero external load, then the load is applied in ``load_steps`` equal increments.
    """
    loads = np.asarray(loads, float)
    B = loads.shape[0]
    if x0 is None:
        x0, R0 = model.reference_state(B)
    x, R = np.array(x0, float), np.array(R0, float)
    alive = np.ones(B, bool)
    frac = np.zeros(B)
    iters = np.zeros(B, int)
    res_f = np.zeros(B)
    res_m = np.zeros(B)
    for k in range(0, load_steps + 1):
        lam = k / load_steps
        idx = np.flatnonzero(alive)
        if idx.size == 0:
            break
        L = lam * loads[idx]
        xs, Rs, conv, rf, rm, it = newton(
            model, x[idx], R[idx], L, _take(fmask, idx, B), _take(cmask, idx, B),
            _take_params(params, idx, B), max_iter, tol_force, tol_moment, **kw)
        iters[idx] += it
        res_f[idx], res_m[idx] = rf, rm
        ok = idx[conv]
        x[ok], R[ok] = xs[conv], Rs[conv]
        frac[ok] = lam
        bad = idx[~conv]
        if bad.size:
            alive[bad] = False
            log.warning("equilibrium not reached for %d scenario(s) at load fraction %.2f "
                        "(max residual %.2e N, %.2e N*m)", bad.size, lam, rf[~conv].max(), rm[~conv].max())
    return SolveResult(x, R, alive, res_f, res_m, iters, frac)
