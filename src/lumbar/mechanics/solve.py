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

from . import profile, so3
from .model import SpineModel

log = logging.getLogger(__name__)

LENGTH_SCALE = 0.05  # m, converts moments to forces in the merit function
#: Largest residual force [N] and moment [N*m] of a state reported as an equilibrium, whatever tolerance the
#: caller asked for (the workflow schema bounds solver.tol_force_n / tol_moment_nm by the same values): a
#: looser tolerance could otherwise report the unloaded start state as "converged" under a 10 N*m load.
PHYSICAL_TOL_FORCE_N = 1e-3
PHYSICAL_TOL_MOMENT_NM = 1e-4


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
    S = _scaling(nb)
    As = A * S[:, None] * S[None, :]
    sym = 0.5 * (As + np.swapaxes(As, -1, -2))
    lam = np.linalg.eigvalsh(sym)[:, 0]
    scale = np.abs(np.diagonal(sym, axis1=-2, axis2=-1)).max(-1)
    mu = np.where(lam < 1e-8 * scale, -lam + 1e-6 * scale, 0.0)
    As = As + mu[:, None, None] * np.eye(n)
    d = np.linalg.solve(As, (S * Q)[..., None])[..., 0] * S
    return d.reshape(-1, nb, 6)


def _regularisation(nb, damping):
    return np.tile(np.repeat(np.asarray(damping, float)[:2], 3), nb)


def _scaling(nb):
    """Variable scaling of the modified Newton step: rotations by LENGTH_SCALE."""
    return np.tile(np.repeat([1.0, 1.0 / LENGTH_SCALE], 3), nb)


def newton(model, x, R, loads, fmask=1.0, cmask=1.0, params=None, max_iter=50, tol_force=1e-8,
           tol_moment=1e-8, max_step_trans=1e-3, max_step_rot=0.05, damping=(1.0, 1e-6)):
    """Damped modified Newton on a batch; returns (x, R, converged, res_f, res_m, iterations).

    A :class:`lumbar.mechanics.model.SpineModel` is solved on the compiled core when it is active
    (:func:`lumbar.mechanics.kernel.newton`: the same iteration, scenario by scenario); any other model (e.g. the
    muscle model, which adds its own terms to the SpineModels' residuals) and the reference mode run
    :func:`newton_reference`."""
    from . import kernel  # noqa: PLC0415 - numba only where equilibria are computed (lumbar/__init__.py)
    profile.count("equilibria", x.shape[0])
    with profile.phase("fsu_solve"):
        return _newton_dispatch(kernel, model, x, R, loads, fmask, cmask, params, max_iter, tol_force, tol_moment,
                                max_step_trans, max_step_rot, damping)


def _newton_dispatch(kernel, model, x, R, loads, fmask, cmask, params, max_iter, tol_force, tol_moment,
                     max_step_trans, max_step_rot, damping):
    if isinstance(model, SpineModel) and type(model).evaluate is SpineModel.evaluate and kernel.active() \
            and model.kernel_supported():
        nb = x.shape[1]
        return kernel.newton(model, x, R, loads, fmask, cmask, params, max_iter, tol_force, tol_moment,
                             max_step_trans, max_step_rot, _regularisation(nb, damping), _scaling(nb), LENGTH_SCALE)
    return newton_reference(model, x, R, loads, fmask, cmask, params, max_iter, tol_force, tol_moment,
                            max_step_trans, max_step_rot, damping)


def newton_reference(model, x, R, loads, fmask=1.0, cmask=1.0, params=None, max_iter=50, tol_force=1e-8,
                     tol_moment=1e-8, max_step_trans=1e-3, max_step_rot=0.05, damping=(1.0, 1e-6)):
    """Damped modified Newton on a batch, vectorised numpy (the reference of the compiled core); returns
    (x, R, converged, res_f, res_m, iterations).

    The line search evaluates its trial states with the Jacobian, so an accepted trial (the
    usual case, full step) provides the residual and Jacobian of the next iteration.
    """
    B, nb = x.shape[:2]
    n = 6 * nb
    x, R = x.copy(), R.copy()
    conv = np.zeros(B, bool)
    iters = np.zeros(B, int)
    res_f = np.full(B, np.inf)
    res_m = np.full(B, np.inf)
    reg = _regularisation(nb, damping)

    def sub(idx):
        return (_take(loads, idx, B), _take(fmask, idx, B), _take(cmask, idx, B), _take_params(params, idx, B))

    active = np.arange(B)
    La, fm, cm, pa = sub(active)
    Q, J = model.evaluate(x, R, La, fm, cm, jacobian=True, params=pa)
    for it in range(max_iter + 1):
        rf, rm = _residual_norms(Q)
        res_f[active], res_m[active] = rf, rm
        done = (rf < tol_force) & (rm < tol_moment)
        conv[active[done]] = True
        if it == max_iter:
            break
        keep = ~done
        active, Q, J = active[keep], Q[keep], J[keep]
        if active.size == 0:
            break
        La, fm, cm, pa = sub(active)
        xa, Ra = x[active], R[active]
        d = _modified_newton_step(-J.reshape(-1, n, n) + np.diag(reg), Q.reshape(-1, n), nb)
        st = np.linalg.norm(d[..., :3], axis=-1).max(-1) / max_step_trans
        sr = np.linalg.norm(d[..., 3:], axis=-1).max(-1) / max_step_rot
        d = d / np.maximum(1.0, np.maximum(st, sr))[:, None, None]
        m0 = _merit(Q)
        alpha = np.ones(active.size)
        accepted = np.zeros(active.size, bool)
        xn, Rn = xa.copy(), Ra.copy()
        Qn, Jn = np.empty_like(Q), np.empty_like(J)
        todo = np.arange(active.size)
        for _ls in range(10):
            xt = xa[todo] + alpha[todo, None, None] * d[todo, :, :3]
            Rt = so3.exp(alpha[todo, None, None] * d[todo, :, 3:]) @ Ra[todo]
            sa = active[todo]
            Lt, ft, ct, pt = sub(sa)
            Qt, Jt = model.evaluate(xt, Rt, Lt, ft, ct, jacobian=True, params=pt)
            ok = _merit(Qt) < m0[todo] * (1.0 - 1e-4 * alpha[todo])
            last = _ls == 9
            # where no decrease was found (a local minimum of the merit, e.g. at the torque minimum
            # of Eq. 3 with p3 < 0), the last trial is the full step-limited step, to hop over it
            if last:
                ok[:] = True
            take = todo[ok]
            xn[take], Rn[take], Qn[take], Jn[take] = xt[ok], Rt[ok], Qt[ok], Jt[ok]
            accepted[take] = True
            todo = todo[~ok]
            if todo.size == 0:
                break
            alpha[todo] = 1.0 if _ls == 8 else alpha[todo] * 0.5
        x[active], R[active] = xn, Rn
        Q, J = Qn, Jn
        iters[active] += 1
    return x, R, conv, res_f, res_m, iters


def _continuation(model, loads, x, R, fmask, cmask, params, load_steps, max_iter, tol_force, tol_moment, kw):
    B = loads.shape[0]
    alive = np.ones(B, bool)
    frac = np.zeros(B)
    iters = np.zeros(B, int)
    res_f = np.zeros(B)
    res_m = np.zeros(B)
    x, R = x.copy(), R.copy()
    for k in range(1, load_steps + 1):
        lam = k / load_steps
        idx = np.flatnonzero(alive)
        if idx.size == 0:
            break
        xs, Rs, conv, rf, rm, it = newton(
            model, x[idx], R[idx], lam * loads[idx], _take(fmask, idx, B), _take(cmask, idx, B),
            _take_params(params, idx, B), max_iter, tol_force, tol_moment, **kw)
        iters[idx] += it
        res_f[idx], res_m[idx] = rf, rm
        ok = idx[conv]
        x[ok], R[ok] = xs[conv], Rs[conv]
        frac[ok] = lam
        alive[idx[~conv]] = False
    return x, R, alive, res_f, res_m, iters, frac


def solve(model, loads, x0=None, R0=None, fmask=1.0, cmask=1.0, params=None, load_steps=1,
          retry_load_steps=(4, 16), max_iter=50, tol_force=1e-8, tol_moment=1e-8, **kw) -> SolveResult:
    """Equilibrium under ``loads`` (B, nb, 6) from the start state (default: reference).

    The full load is applied in ``load_steps`` increments (one by default: the modified Newton
    with step limits is robust for these models). Scenarios that fail are retried from their
    start state with finer load continuation (``retry_load_steps``); those that still fail are
    returned with ``converged = False``, frozen at the last load fraction they reached, and logged.
    """
    loads = np.asarray(loads, float)
    B = loads.shape[0]
    if not (tol_force > 0 and tol_moment > 0):
        raise ValueError(f"solver tolerances must be > 0, got tol_force={tol_force!r} N, tol_moment={tol_moment!r} N*m")
    if tol_force > PHYSICAL_TOL_FORCE_N or tol_moment > PHYSICAL_TOL_MOMENT_NM:
        log.warning("solver tolerances %.1e N, %.1e N*m are looser than the physical limit of an equilibrium "
                    "(%.0e N, %.0e N*m): using the limit", tol_force, tol_moment, PHYSICAL_TOL_FORCE_N,
                    PHYSICAL_TOL_MOMENT_NM)
        tol_force, tol_moment = min(tol_force, PHYSICAL_TOL_FORCE_N), min(tol_moment, PHYSICAL_TOL_MOMENT_NM)
    if x0 is None:
        x0, R0 = model.reference_state(B)
    x0, R0 = np.asarray(x0, float), np.asarray(R0, float)
    x, R, conv, res_f, res_m, iters, frac = _continuation(
        model, loads, x0, R0, fmask, cmask, params, load_steps, max_iter, tol_force, tol_moment, kw)
    for steps in retry_load_steps:
        bad = np.flatnonzero(~conv)
        if bad.size == 0:
            break
        out = _continuation(model, loads[bad], x0[bad], R0[bad], _take(fmask, bad, B), _take(cmask, bad, B),
                            _take_params(params, bad, B), steps, max_iter, tol_force, tol_moment, kw)
        better = out[2] | (out[6] > frac[bad])
        sel = bad[better]
        x[sel], R[sel], conv[sel] = out[0][better], out[1][better], out[2][better]
        res_f[sel], res_m[sel], frac[sel] = out[3][better], out[4][better], out[6][better]
        iters[bad] += out[5]
    conv = conv & (res_f <= PHYSICAL_TOL_FORCE_N) & (res_m <= PHYSICAL_TOL_MOMENT_NM)   # never a looser "converged"
    if not conv.all():
        log.info("equilibrium not reached for %d of %d scenario(s) (max residual %.2e N, %.2e N*m); "
                 "flagged converged=False", int((~conv).sum()), B, res_f[~conv].max(), res_m[~conv].max())
    return SolveResult(x, R, conv, res_f, res_m, iters, frac)


def stable_rest_states(model, x, R, fmask=1.0, cmask=1.0, params=None, rtol=1e-9) -> np.ndarray:
    """(B,) bool: the unloaded states (x, R) are stable, i.e. the symmetric part of the tangent stiffness (-dQ/dx,
    rotations scaled by LENGTH_SCALE as in the Newton step) has no negative eigenvalue below -``rtol`` x its
    largest magnitude (a neutral direction, zero up to round-off, counts as stable). An equilibrium that is not
    stable (a saddle: a law with negative stiffness about its rest state) is one a specimen would leave at the
    slightest load, so a range of motion measured from it includes that snap."""
    _, J = model.evaluate(x, R, fmask=fmask, cmask=cmask, params=params)
    n = 6 * model.nb
    S = _scaling(model.nb)
    A = -J.reshape(-1, n, n) * S[:, None] * S[None, :]
    w = np.linalg.eigvalsh(0.5 * (A + np.swapaxes(A, -1, -2)))
    return w.min(axis=-1) >= -rtol * np.abs(w).max(axis=-1)


def continue_rest_states(model, res: SolveResult, fmask, cmask, params=None, steps=(8, 32), **kw) -> SolveResult:
    """Rest states (0 N*m, no load) of B element sets, rows of ``fmask`` / ``cmask`` in removal order (the stages of
    a reduction), after :func:`solve` from the reference: a row that did not converge there is continued from the
    previous row's rest state, its removed elements' weights going from the previous row's to its own in ``steps``
    equal increments (each count of ``steps`` in turn until one reaches the end) - the state a specimen settles in
    when the structure is cut. Where a unit has more than one stable rest state (a disc law with negative stiffness
    about zero, held by a weak ligament) the reference is a saddle the modified Newton cannot leave toward either, and
    this is the state the sequence of cuts leads to. Rows reached from the reference, and rows whose previous row has
    no rest state, are left as they are; ``res`` is updated in place and returned."""
    B = len(res.converged)
    fm, cm = np.broadcast_to(np.asarray(fmask, float), (B, model.nf)), np.broadcast_to(np.asarray(cmask, float),
                                                                                        (B, model.nc))
    zero = np.zeros((1, model.nb, 6))
    for i in range(1, B):
        if res.converged[i] or not res.converged[i - 1]:
            continue
        for n in steps:
            x, R, it, ok = res.x[i - 1:i], res.R[i - 1:i], 0, True
            for t in np.arange(1, n + 1) / n:
                r = solve(model, zero, x0=x, R0=R, fmask=fm[i - 1:i] * (1.0 - t) + fm[i:i + 1] * t,
                          cmask=cm[i - 1:i] * (1.0 - t) + cm[i:i + 1] * t, params=_take_params(params, [i], B),
                          retry_load_steps=(), **kw)
                x, R, it = r.x, r.R, it + int(r.iterations[0])
                if not r.converged[0]:
                    ok = False
                    break
            res.iterations[i] += it
            if ok:
                res.x[i], res.R[i], res.converged[i] = x[0], R[0], True
                res.residual_force[i], res.residual_moment[i] = r.residual_force[0], r.residual_moment[0]
                res.load_fraction[i] = 1.0
                log.info("rest state %d of %d not reached from the reference: reached from rest state %d by removing "
                         "the elements they differ by in %d steps", i, B, i - 1, n)
                break
    return res


def solve_sequence(model, loads_path, x0=None, R0=None, fmask=1.0, cmask=1.0, params=None, **kw) -> list:
    """Equilibria along a load path (a continuation): ``loads_path`` (K, B, nb, 6), step k warm-started from the
    equilibrium of step k-1 (the first from ``x0, R0``, default the reference state).

    ``fmask`` / ``cmask`` are shared by every step, or given per step with a leading axis K (e.g. a follower-load
    cable whose weight grows). Returns the K :class:`SolveResult` objects. A scenario that does not converge at a step
    is flagged there (``converged`` False) and the next step starts from its last state, so a jump of the solution
    between two close load levels stays visible instead of being smoothed over by a fresh start."""
    loads_path = np.asarray(loads_path, float)
    K, B = loads_path.shape[:2]

    def at(a, k):
        a_arr = np.asarray(a, float)
        return a_arr[k] if a_arr.ndim == 3 and a_arr.shape[0] == K else a

    if x0 is None:
        x0, R0 = model.reference_state(B)
    x, R = np.asarray(x0, float), np.asarray(R0, float)
    out = []
    for k in range(K):
        res = solve(model, loads_path[k], x0=x, R0=R, fmask=at(fmask, k), cmask=at(cmask, k), params=params, **kw)
        x, R = res.x, res.R
        out.append(res)
    return out
