"""Muscle redundancy: activations and vertebral poses in static equilibrium (paper 2, Sect. 2.2, static).

Problem: find activations ``a`` in [0, 1] (and the poses ``q`` of all free bodies, which follow from
static equilibrium ``Q(q, a) = 0``) minimising

    w_a * sum a^2 + w_f * sum_levels |F_level(q)|^2 + w_t * |thorax rotation(q) - target|^2

(the paper's cost without its time terms; F_level = force [N] and moment / 0.05 m of each level's passive
structures; tracking error in degrees). Method: sequential QP with exact sensitivities. At an equilibrium
``(q, a)``, ``dq = -J^-1 (Q + B da)`` with ``J = dQ/dq`` (exact, from the model) and ``B = dQ/da``;
the cost is linearised in ``da`` through ``dq`` and minimised over the box ``max(-a, -D) <= da <=
min(1 - a, D)`` by OSQP (qpsolvers, sparse matrices, activations as variables); then the equilibrium for
the new activations is solved by Newton (``lumbar.solve.solve``) from the predicted pose. A step is kept if
the true cost decreases, else the trust radius D is halved. Every returned state is an equilibrium
(residual below ``tol``); a posture whose thorax misses its target by more than ``max_tracking_deg`` is
flagged ``converged = False`` (the paper's red stars).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .. import so3
from ..solve import solve

log = logging.getLogger(__name__)


@dataclass
class Weights:
    activation: float = 1.0
    fsu_load_per_n2: float = 1.0e-6
    tracking_per_deg2: float = 1.0e4
    length_scale_m: float = 0.05

    def __post_init__(self):
        for k, v in vars(self).items():
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"cost weight {k} must be finite and >= 0, got {v}")


@dataclass
class PostureSolution:
    x: np.ndarray                  # (nb, 3)
    R: np.ndarray                  # (nb, 3, 3)
    a: np.ndarray                  # (nm,)
    converged: bool                # equilibrium reached and tracking error <= max_tracking_deg
    equilibrium: bool
    tracking_error_deg: float
    residual_force_n: float
    residual_moment_nm: float
    cost: float
    iterations: int
    message: str = ""


def _rot_target(theta_deg):
    t = np.radians(theta_deg)
    return np.array([0.0, t, 0.0])


class _ThoraxFixed:
    """The model with the thorax rotation held (its three rotational DOFs removed from the Newton solve)."""

    def __init__(self, model):
        self.m, self.nb = model, model.nb

    def reference_state(self, batch=1):
        return self.m.reference_state(batch)

    def evaluate(self, x, R, loads=None, fmask=1.0, cmask=1.0, jacobian=True, params=None):
        Q, J = self.m.evaluate(x, R, loads, jacobian=jacobian, params=params)
        t = self.m.thorax
        Q[:, t, 3:] = 0.0
        if J is not None:
            J[:, t, 3:] = 0.0
            J[:, :, :, t, 3:] = 0.0
            J[:, t, 3:, t, 3:] = -np.eye(3)
        return Q, J


class RedundancySolver:
    """Static redundancy solver; the thorax rotation is prescribed (a constraint), so the muscles must
    balance the thorax's moment exactly: that is an equality constraint of each QP. A posture the muscles
    cannot hold (constraint infeasible within a in [0, 1]) is flagged ``converged = False``."""

    def __init__(self, model, weights: Weights | None = None, tol=1e-7, max_iter=40, trust0=0.3):
        self.m = model
        self.fixed = _ThoraxFixed(model)
        self.w = weights or Weights()
        self.tol, self.max_iter, self.trust0 = tol, max_iter, trust0
        n = model.nb * 6
        t = model.thorax
        self.rot = np.arange(6 * t + 3, 6 * t + 6)
        self.free = np.setdiff1d(np.arange(n), self.rot)

    def _equilibrium(self, x0, R0, a, params):
        p = dict(params, activation=a[None])
        res = solve(self.fixed, np.zeros((1, self.m.nb, 6)), x0=x0[None], R0=R0[None], params=p,
                    max_iter=80, tol_force=self.tol, tol_moment=self.tol, retry_load_steps=())
        return res.x[0], res.R[0], bool(res.converged[0])

    def _levels(self, x, R):
        F, D = self.m.level_loads(x[None], R[None], jacobian=True)
        s = np.r_[np.ones(3), np.full(3, 1.0 / self.w.length_scale_m)]
        return (F[0] * s).reshape(-1), (D[0] * s[None, :, None, None]).reshape(F[0].size, -1)

    def cost(self, x, R, a):
        F, _ = self._levels(x, R)
        return float(self.w.activation * a @ a + self.w.fsu_load_per_n2 * F @ F)

    def thorax_moment(self, x, R, a, params):
        Q, _ = self.m.evaluate(x[None], R[None], params=dict(params, activation=a[None]), jacobian=False)
        return Q[0, self.m.thorax, 3:]

    def _linearise(self, x, R, a, params):
        """dq_free/da and dq_free at da=0 (free DOFs), thorax moment M and dM/da (through dq)."""
        m = self.m
        n = m.nb * 6
        Q, J = m.evaluate(x[None], R[None], params=dict(params, activation=a[None]))
        Q, J = Q.reshape(n), J.reshape(n, n)
        L, Gd = m.paths.lengths(x[None], R[None])
        props = params.get("props", m.props)
        act1 = props.tension(L, 1.0)[2][0]
        Bm = -(Gd[0].reshape(m.ms.n, n) * act1[:, None]).T       # dQ/da (n, nm)
        f, r = self.free, self.rot
        sol = np.linalg.solve(J[np.ix_(f, f)], np.c_[Q[f], Bm[f]])
        dq0_f, S_f = -sol[:, 0], -sol[:, 1:]
        M0 = Q[r] + J[np.ix_(r, f)] @ dq0_f
        SM = Bm[r] + J[np.ix_(r, f)] @ S_f
        S = np.zeros((n, m.ms.n))
        dq0 = np.zeros(n)
        S[f], dq0[f] = S_f, dq0_f
        return S, dq0, M0, SM

    def solve(self, target_flexion_deg, params, x0=None, R0=None, a0=None) -> PostureSolution:
        import qpsolvers  # noqa: PLC0415
        m, w = self.m, self.w
        nm = m.ms.n
        a = np.zeros(nm) if a0 is None else np.clip(np.asarray(a0, float), 0, 1)
        if x0 is None:
            x0, R0 = self._initial_pose(target_flexion_deg)
        x, R, eq = self._equilibrium(x0, R0, a, params)
        if not eq:
            return PostureSolution(x, R, a, False, False, np.nan, np.nan, np.nan, np.nan, 0,
                                   "no equilibrium of the free vertebrae at the initial activations")
        D = self.trust0
        c = np.inf
        it = 0
        Mn = self.thorax_moment(x, R, a, params)
        for it in range(1, self.max_iter + 1):
            S, dq0, M0, SM = self._linearise(x, R, a, params)
            F, DF = self._levels(x, R)
            SF, rF = DF @ S, F + DF @ dq0
            P = 2 * (w.activation * np.eye(nm) + w.fsu_load_per_n2 * SF.T @ SF)
            q = 2 * (w.activation * a + w.fsu_load_per_n2 * SF.T @ rF)
            accepted = False
            while D > 1e-6:
                lb, ub = np.maximum(-a, -D), np.minimum(1 - a, D)
                da = qpsolvers.solve_qp(sp.csc_matrix(0.5 * (P + P.T)), q, A=sp.csc_matrix(SM), b=-M0,
                                        lb=lb, ub=ub, solver="osqp", eps_abs=1e-9, eps_rel=1e-9,
                                        max_iter=40000, polish=True, verbose=False)
                if da is None:      # moment not balanced within the box: least-squares fallback
                    Pm = P * 1e-6 + 2 * SM.T @ SM
                    da = qpsolvers.solve_qp(sp.csc_matrix(Pm), 2 * SM.T @ M0 + 1e-6 * q, lb=lb, ub=ub,
                                            solver="osqp", eps_abs=1e-9, eps_rel=1e-9, max_iter=40000,
                                            polish=True, verbose=False)
                    if da is None:
                        D *= 0.5
                        continue
                da = np.clip(da, lb, ub)
                dq = (dq0 + S @ da).reshape(m.nb, 6)
                an = a + da
                xn, Rn, eqn = self._equilibrium(x + dq[:, :3], so3.exp(dq[:, 3:]) @ R, an, params)
                if eqn:
                    Mn_ = self.thorax_moment(xn, Rn, an, params)
                    cn = self.cost(xn, Rn, an)
                    better_m = np.abs(Mn_).max() < max(np.abs(Mn).max() * 0.999, self.tol)
                    if better_m or (np.abs(Mn_).max() <= max(np.abs(Mn).max(), 1e-6) and cn < c):
                        step = np.abs(da).max()
                        x, R, a, c, Mn = xn, Rn, an, cn, Mn_
                        accepted = True
                        D = min(1.0, 2 * D) if step > 0.9 * D else D
                        break
                D *= 0.5
            if not accepted or (step < 1e-7 and np.abs(Mn).max() < self.tol):
                break
        Q, _ = m.evaluate(x[None], R[None], params=dict(params, activation=a[None]), jacobian=False)
        rf, rm = float(np.abs(Q[0, :, :3]).max()), float(np.abs(Q[0, :, 3:]).max())
        ok = rf < 1e-6 and rm < 1e-6
        e = float(np.degrees(np.linalg.norm(so3.log(R[m.thorax]) - _rot_target(target_flexion_deg))))
        msg = "" if ok else f"muscles cannot balance the thorax at the target (max residual moment {rm:.3g} N*m)"
        return PostureSolution(x, R, a, ok, True, e if ok else np.nan, rf, rm, self.cost(x, R, a), it, msg)

    def _initial_pose(self, theta_deg):
        """Reference pose with the thorax rotation spread evenly over the five levels (about each level's
        disc centre)."""
        m = self.m
        x, R = m.reference_state()
        x, R = x[0], R[0]
        levels = ["L5-S1", "L4-L5", "L3-L4", "L2-L3", "L1-L2"]
        order = ["L5", "L4", "L3", "L2", "L1"]
        step = so3.exp(np.array([0, np.radians(theta_deg) / 5, 0]))
        for k, lv in enumerate(levels):
            piv = np.asarray(m.geo.levels[lv].disc_centre, float)
            lower = m.geo.levels[lv].lower
            if lower != "S1":
                bi = m.body_index[lower]
                piv = x[bi] + R[bi] @ (piv - m.c[bi])
            for v in order[k:]:
                b = m.body_index[v]
                x[b] = piv + step @ (x[b] - piv)
                R[b] = step @ R[b]
        return x, R
