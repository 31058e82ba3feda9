"""Muscle redundancy: activations and vertebral poses in static equilibrium (paper 2, Sect. 2.2, static).

Problem, per posture (L1..L5 free, the thorax = the L1 body, its rotation tracked):

    minimise   w_a * sum a^2 + w_f * sum_levels |F_level(q)|^2 + w_t * |thorax rotation(q) - target|_deg^2
    subject to Q(q, a) = 0  (static equilibrium of every free body),  0 <= a <= 1

(the paper's cost without its time terms; ``F_level`` = force [N] and moment / 0.05 m of each level's
passive structures on its upper vertebra). Weights are fixed once (``Weights``), not fitted.

Method: sequential quadratic programming with exact first derivatives, in two phases.

* Phase 0 (start): the thorax rotation is held at its target; the other DOFs are put in equilibrium by
  :func:`lumbar.mechanics.solve.solve`, then SQP steps balance the thorax moment (a heavily weighted least-squares
  row), so that phase 1 starts close to equilibrium.
* Phase 1: all DOFs free. Each QP has the poses and activations as variables, the Gauss-Newton model of
  the cost, the linearised equilibrium ``J dq + B da = -Q`` as an equality (``J = dQ/dq`` exact from the
  model, ``B = dQ/da = -(dL/dq)^T F_iso``) and the activation box (within the trust bound D). The equality
  is eliminated exactly (J is invertible), ``dq = -J^-1 (Q + B da)``; the remaining bound-constrained linear
  least squares in ``da`` is solved exactly by :func:`box_lsq`. Steps are capped (1 mm, 0.02 rad) and
  accepted by an Armijo test on the L1 merit ``cost + mu |Q|_1`` over six step lengths evaluated as one
  batch, each trial point first brought back onto the equilibrium manifold by up to ``restore_iter``
  Newton steps on the poses with its activations fixed (a second-order correction: the QP step balances
  the bodies only to first order, and on the curved manifold of an S-shaped spine holding a crate the
  merit otherwise rejected every step length); if none decreases it while out of equilibrium, ``mu``
  (below the equilibrium multipliers, so the step was no descent direction) is raised tenfold up to
  ``mu_max`` and the step retried. Stop when the KKT residual (below) is under ``kkt_tol / 2``, or (a stall)
  the QP's predicted cost decrease is below ``rel_cost_tol`` (relative), with a residual below
  ``polish_from``; a scenario whose line search failed off equilibrium is solved once more with a longer line
  search (``retry_line_search``); a plain Newton polish on the poses (activations fixed) then brings the residual
  of every free body below ``tol`` (1e-8 N and N*m).

All scenarios of a batch advance together (one vectorised model evaluation per iteration). A posture is
``reached`` if the equilibrium holds (< 1e-6) and the thorax is within ``max_tracking_deg`` (1 deg, the
paper's rejection rule, red stars) of its target; ``certified`` if it is reached and its KKT residual
(:meth:`RedundancySolver.kkt_residuals`: stationarity of the Lagrangian with least-squares equilibrium
multipliers and the activation-bound complementarity, from the same exact derivatives) is <= ``kkt_tol``
(1e-4, relative); ``converged`` = certified. Otherwise it is flagged with a message and a log line, never
returned as a silent number.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from ..mechanics import so3
from ..mechanics.solve import solve
from .qp import box_lsq

log = logging.getLogger(__name__)


@dataclass
class Weights:
    """Cost weights, chosen once (documented in docs/design.md), not fitted to the validation data."""

    activation: float = 1.0              # per activation^2
    fsu_load_per_n2: float = 1.0e-6      # per N^2 of level force (moments / length_scale_m)
    tracking_per_deg2: float = 1.0e3     # per deg^2 of thorax rotation error
    length_scale_m: float = 0.05

    def __post_init__(self):
        for k, v in vars(self).items():
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"cost weight {k} must be finite and >= 0, got {v}")
        if not self.length_scale_m > 0:
            raise ValueError(f"cost weight length_scale_m must be > 0 m, got {self.length_scale_m}")


@dataclass
class PostureSolution:
    x: np.ndarray                  # (nb, 3)
    R: np.ndarray                  # (nb, 3, 3)
    a: np.ndarray                  # (nm,)
    converged: bool                # equilibrium, SQP terminated, tracking error <= max_tracking_deg
    equilibrium: bool
    tracking_error_deg: float
    residual_force_n: float
    residual_moment_nm: float
    cost: float
    iterations: int
    message: str = ""
    reached: bool = True           # equilibrium and tracking error <= max_tracking_deg (no red star); a reached
    #                                posture that is not ``converged`` is an equilibrium on target whose
    #                                optimality the SQP could not certify
    kkt_residual: float = float("nan")   # first-order optimality measure: IPOPT's NLP error where the solver
    #                                has a certifier (lumbar.muscles.nlp), else RedundancySolver.kkt_residuals
    certified: bool = False        # reached and the certifier's (else the SQP's) test passed
    sqp_kkt_residual: float = float("nan")   # the SQP's own KKT measure (relative)
    ipopt_status: str = ""         # IPOPT's return status of the certification ("" without a certifier)
    optimum: str = "sqp"           # path of the reported optimum: sqp (certified by IPOPT if it has a certifier),
    #                                ipopt_cold (IPOPT from the cold start found a lower-cost optimum)
    other_cost: float = float("nan")   # cost of the other path's certified optimum (multistart), else NaN


def rot_target(theta_deg):
    """Thorax rotation vector [rad] of a sagittal target (flexion +, about +y)."""
    return np.array([0.0, np.radians(theta_deg), 0.0])


class _ThoraxHeld:
    """The model with the thorax rotation held (its three rotational equations replaced by dtheta = 0)."""

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


@dataclass
class _Batch:
    """The state of a batch of postures during the SQP (RedundancySolver._solve_batch): poses, activations, the
    model state (``st``: Q, J, cost, ...), per scenario the trust bound, the merit weight, the flags of the two
    phases (``stop``: phase 0; ``done``, ``optimal``: phase 1), iterations, the QP's warm start and the message."""
    x: np.ndarray
    R: np.ndarray
    a: np.ndarray
    st: dict
    params: dict
    targets: np.ndarray
    D: np.ndarray
    mu: np.ndarray
    done: np.ndarray
    optimal: np.ndarray
    stop: np.ndarray
    iters: np.ndarray
    warm: list
    msg: list
    costs: list = None       # phase 1: each scenario's cost after each iteration (the hand-over test)


@dataclass
class _Trials:
    """The line search's trial points of one iteration: merit per scenario and step length, poses, activations
    and model states (rows: scenario x step length)."""
    m_new: np.ndarray
    xn: np.ndarray
    Rn: np.ndarray
    an: np.ndarray
    sn: dict


class RedundancySolver:
    """Batched feasible SQP for the static muscle redundancy problem (module docstring)."""

    def __init__(self, model, weights: Weights | None = None, tol=1e-8, max_iter=40, trust0=0.25,
                 step_tol=1e-6, max_tracking_deg=1.0):
        if not max_tracking_deg > 0:
            raise ValueError(f"max_tracking_deg must be > 0 deg, got {max_tracking_deg}")
        if not (0 < tol <= 1e-6):
            raise ValueError(f"equilibrium tolerance must be in (0, 1e-6] N and N*m, got {tol}")
        self.m = model
        self.w = weights or Weights()
        self.tol, self.max_iter, self.trust0 = tol, int(max_iter), trust0
        self.step_tol, self.max_tracking_deg = step_tol, max_tracking_deg
        t = model.thorax
        self.rot = np.arange(6 * t + 3, 6 * t + 6)
        nb = model.nb
        ls = self.w.length_scale_m
        self.fscale = np.r_[np.ones(3), np.full(3, 1.0 / ls)]
        self.qscale = np.tile(self.fscale, nb)                       # residual rows: N, N*m / 0.05 m
        self.qvar = np.tile(np.r_[np.full(3, 1e-3), np.full(3, 1e-2)], nb)   # QP pose variables: mm, 10 mrad
        self.dq_max = np.full(6 * nb, 2.0)                           # |dq| <= 2 mm, 20 mrad at D = trust0
        self.mu0 = 1.0                                              # L1 merit weight per N of residual
        self.mu_max = 1.0e6          # the merit weight is raised x10 (up to this) when a step fails the search
        self.accept_suboptimal = False
        self.line_search = (1.0, 0.5, 0.25, 0.1, 0.03, 0.01)
        self.retry_line_search = (1.0, 0.5, 0.25, 0.1, 0.03, 0.01, 0.003, 0.001)   # see solve_batch
        self.free = np.setdiff1d(np.arange(6 * nb), self.rot)
        self.w_moment = 1.0e2          # phase 0: per (N*m / 0.05 m)^2 of thorax moment
        self.phase0_iter = 40
        self.rel_cost_tol = 1e-9     # stall: predicted cost decrease of the QP step, relative (1e-6 stopped
        #                              flexion at KKT residual 3e-4; with 1e-9 and step_tol 1e-6 it is certified)
        self.polish_from = 1e-3      # N, N*m: residual below which the final Newton polish takes over
        self.max_step_m, self.max_step_rad = 1e-3, 0.02   # per-iteration step limits of the poses
        self.restore_iter = 4        # Newton corrections of each trial point back onto equilibrium
        self.batch_size = 64         # postures advanced together by the callers' batched loops (muscle_model)
        self.polish_start = "primal"  # IPOPT's start where the SQP point fails the certificate (nlp.options)
        self.full_step_first = True  # line search: the full step alone first (False: every step length at once,
        #                              the same step chosen at 2-3x the cost; kept for benchmarks/)
        # start (cold): for thorax targets beyond start_min_deg, the free vertebrae are first put in
        # equilibrium with the thorax held (a = 0, up to start_iter Newton iterations); nearer the reference
        # posture the SQP starts from the reference pose directly (the passive spine under gravity alone
        # stalls that Newton, which cost 5 s of a 6 s standing solve)
        self.start_iter, self.start_min_deg = 40, 5.0
        self.kkt_tol = 1e-4          # certified: reached and kkt_residual <= kkt_tol (relative, see kkt_residuals)
        self.certifier = None        # an IpoptPostureSolver (lumbar.muscles.nlp): certifies every reached optimum
        self.multistart = False      # cold solves: also IPOPT alone from the cold start; the lower certified cost wins
        self.multistart_max_iter = 150
        # hand-over to IPOPT (phase 1, only with a certifier): a scenario that is reached (equilibrium, thorax on
        # target) and whose cost fell by less than ``handover_rel`` (relative) over its last ``handover_window``
        # iterations stops; IPOPT polishes it from there (as every reached point that fails its test). The SQP
        # stalls at such points (line search or KKT residual ~1 for up to its whole budget) where IPOPT
        # certifies in a few iterations; unreached scenarios keep their whole budget. 0: off.
        self.handover_window = 0
        self.handover_rel = 1e-4

    # ------------------------------------------------------------------ pieces
    def _params(self, params, a, idx):
        p = {k: (v[idx] if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == self._B else v)
             for k, v in params.items()}
        p["activation"] = a
        return p

    def tracking(self, R, targets_deg):
        """Thorax tracking error [deg] (B, 3) and its derivative by the thorax's spatial rotation (B, 3, 3)."""
        phi = so3.log(R[:, self.m.thorax])
        e = np.degrees(phi - np.stack([rot_target(t) for t in np.atleast_1d(targets_deg)]))
        return e, np.degrees(so3.left_jacobian_inverse(phi))

    def cost(self, FL, e, a):
        Fs = FL * self.fscale
        w = self.w
        return (w.activation * (a ** 2).sum(-1) + w.fsu_load_per_n2 * (Fs ** 2).sum((-1, -2))
                + w.tracking_per_deg2 * (e ** 2).sum(-1))

    def _state(self, x, R, a, params, idx, targets):
        """Everything one SQP iteration needs at (x, R, a), for the scenarios ``idx`` (one evaluation)."""
        m = self.m
        p = self._params(params, a, idx)
        Q, J, FL, DL, mus = m.evaluate(x, R, params=p, levels=True, muscles=True)
        e, Te = self.tracking(R, targets)
        Gd, act1 = mus["G"], mus["act1"]
        n = 6 * m.nb
        Bm = -np.swapaxes(Gd.reshape(len(idx), m.ms.n, n) * act1[..., None], 1, 2)   # dQ/da (B, n, nm)
        return dict(Q=Q.reshape(-1, n), J=J.reshape(-1, n, n), FL=FL, DL=DL, e=e, Te=Te, Bm=Bm,
                    c=self.cost(FL, e, a), a=np.array(a, float))

    def evaluate_state(self, x, R, a, params, targets_deg):
        """Public form of :meth:`_state` for a batch whose per-scenario ``params`` match ``x`` (B, nb, 3):
        residual ``Q``, Jacobian ``J``, level loads ``FL``/``DL``, tracking error ``e`` [deg] and its
        derivative ``Te``, ``Bm = dQ/da`` and the cost ``c`` (used by :mod:`lumbar.muscles.nlp`)."""
        self._B = len(x)
        return self._state(x, R, a, params, np.arange(len(x)), np.asarray(targets_deg, float).reshape(-1))

    def _qres(self, st, i, held):
        q = st["Q"][i] * self.qscale
        if held:
            q = q.copy()
            q[..., self.rot] = 0.0
        return q

    def _merit(self, st, mu, held=False):
        if held:     # phase 0: tracking error is 0 by construction; thorax moment penalised
            Fs = st["FL"] * self.fscale
            M = (st["Q"] * self.qscale)[..., self.rot]
            c = (self.w.activation * (st["a"] ** 2).sum(-1) + self.w.fsu_load_per_n2 * (Fs ** 2).sum((-1, -2))
                 + self.w_moment * (M ** 2).sum(-1))
        else:
            c = st["c"]
        return c + mu * np.abs(self._qres(st, slice(None), held)).sum(-1)

    def _qp(self, st, i, a, D, warm, mu, held=False):
        """The trust-region QP of scenario i in (dq, da): Gauss-Newton model of the cost subject to the
        linearised equilibrium ``J dq + B da = -Q`` (equality) and the activation box
        ``max(-a, -D) <= da <= min(1 - a, D)``. The equality is eliminated exactly (J, the stiffness of the
        loaded spine, is invertible): ``dq = dq0 + S da`` with ``J [dq0 S] = -[Q B]``; what remains is a
        bound-constrained linear least-squares problem in ``da``, solved exactly by BVLS (an active-set
        method; scipy.optimize.lsq_linear)."""
        m, w = self.m, self.w
        n, nm = 6 * m.nb, m.ms.n
        J, Q, Bm = st["J"][i], st["Q"][i], st["Bm"][i]
        r = self.rot
        if held:        # phase 0: thorax rotation held, its moment balance a heavily weighted LSQ row
            f = self.free
            sol = np.linalg.solve(J[np.ix_(f, f)], np.c_[Q[f], Bm[f]])
            dq0, S = np.zeros(n), np.zeros((n, nm))
            dq0[f], S[f] = -sol[:, 0], -sol[:, 1:]
            M0 = (Q[r] + J[r] @ dq0) * self.qscale[r]
            SM = (Bm[r] + J[r] @ S) * self.qscale[r][:, None]
        else:
            sol = np.linalg.solve(J, np.c_[Q, Bm])
            dq0, S = -sol[:, 0], -sol[:, 1:]
        DLs = (st["DL"][i] * self.fscale[None, :, None, None]).reshape(-1, n)
        Fs = (st["FL"][i] * self.fscale).reshape(-1)
        Te = st["Te"][i]
        e = st["e"][i]
        sa, sf, stt = np.sqrt(w.activation), np.sqrt(w.fsu_load_per_n2), np.sqrt(w.tracking_per_deg2)
        if held:
            sm = np.sqrt(self.w_moment)
            A = np.vstack([sa * np.eye(nm), sf * DLs @ S, sm * SM])
            b = -np.r_[sa * a, sf * (Fs + DLs @ dq0), sm * M0]
        else:
            A = np.vstack([sa * np.eye(nm), sf * DLs @ S, stt * Te @ S[r]])
            b = -np.r_[sa * a, sf * (Fs + DLs @ dq0), stt * (e + Te @ dq0[r])]
        lb, ub = np.maximum(-a, -D), np.minimum(1.0 - a, D)
        da = box_lsq(w.activation, A[nm:], b[nm:], a, lb, ub)
        r1 = A @ da - b
        self._pred_cost = float(b @ b - r1 @ r1)
        pred = self._pred_cost + mu * np.abs(self._qres(st, i, held)).sum()
        dq = dq0 + S @ da
        return dq, da, pred, None

    def _restored_state(self, x, R, a, params, idx, targets):
        """Second-order correction of trial points: Newton steps on the poses with the activations fixed,
        back onto the equilibrium manifold (the SQP step satisfies equilibrium only to first order; without
        the correction the L1 merit rejects good steps near curved parts of the manifold), up to
        ``restore_iter`` steps, until the residual is below 1e-3 ``tol``. A trial whose Newton step grows (no
        nearby equilibrium) keeps its uncorrected pose (and its residual). Each Newton step uses the full state
        (:meth:`_state`) of its point, so the state of the corrected point comes with the last check instead of
        a further model evaluation. Returns (x, R, state)."""
        x, R = x.copy(), R.copy()
        m = self.m
        live = np.arange(len(x))
        st = None
        for it in range(self.restore_iter + 1):
            s_live = self._state(x[live], R[live], a[live], params, idx[live], targets[live])
            if st is None:
                st = s_live
            else:
                for key, v in s_live.items():
                    st[key][live] = v
            if it == self.restore_iter:
                break
            Qf = s_live["Q"]
            small = np.abs(Qf).max(-1) > 1e-3 * self.tol
            live = live[small]
            if live.size == 0:
                break
            d = -np.linalg.solve(s_live["J"][small], Qf[small][..., None])[..., 0].reshape(-1, m.nb, 6)
            ok = (np.abs(d[..., :3]).max((-1, -2)) < 2 * self.max_step_m) & \
                 (np.abs(d[..., 3:]).max((-1, -2)) < 2 * self.max_step_rad)
            live, d = live[ok], d[ok]
            if live.size == 0:
                break
            x[live] += d[..., :3]
            R[live] = so3.exp(d[..., 3:]) @ R[live]
        return x, R, st

    # ------------------------------------------------------------------ certificate
    def kkt_residuals(self, st, idx=None):
        """First-order (KKT) optimality residual of the posture problem at the states ``st`` (from
        :meth:`_state`), from the solver's own exact derivatives.

        Lagrangian ``f(q, a) + lam^T Q(q, a) - nu_lo^T a + nu_hi^T (a - 1)``. ``lam`` are the least-squares
        multipliers of the equilibrium: they minimise the stationarity residual over the pose rows
        ``grad_q f + J^T lam`` and the rows of the activations strictly inside (0, 1)
        ``grad_a f + B^T lam``; the bound multipliers of the activations at a bound are then what is left,
        ``nu = +-(grad_a f + B^T lam)``, and a wrong sign is a complementarity violation. The residual is
        the largest of: the pose rows (per mm and per 10 mrad of the QP's pose variables), the projected
        activation gradient ``a - clip(a - g_a, 0, 1)`` (stationarity of the free activations and the sign
        of the bound multipliers at once), all relative to ``1 + |grad f|_inf``, and the equilibrium residual
        (N, N*m / length_scale_m) relative to the largest level load. Returns (B,) residuals."""
        m, w = self.m, self.w
        n = 6 * m.nb
        idx = np.arange(len(st["a"])) if idx is None else np.asarray(idx)
        out = np.empty(len(idx))
        from .nlp import BOUND_TOL as bound_tol  # noqa: PLC0415 (an activation this near 0 or 1 is at its bound)
        for k, i in enumerate(idx):
            a = st["a"][i]
            Fs = (st["FL"][i] * self.fscale).reshape(-1)
            DLs = (st["DL"][i] * self.fscale[None, :, None, None]).reshape(-1, n)
            gq = 2.0 * w.fsu_load_per_n2 * (DLs.T @ Fs)
            gq[self.rot] += 2.0 * w.tracking_per_deg2 * (st["Te"][i].T @ st["e"][i])
            ga = 2.0 * w.activation * a
            J, Bm = st["J"][i], st["Bm"][i]
            free = (a > bound_tol) & (a < 1.0 - bound_tol)
            sq = self.qvar                                   # pose rows per QP pose unit (mm, 10 mrad)
            A = np.vstack([(J * sq[None, :]).T, Bm[:, free].T])  # rows: d/dq_j (scaled), d/da_free
            g = np.r_[gq * sq, ga[free]]
            lam = np.linalg.lstsq(A, -g, rcond=None)[0]
            rq = gq * sq + (J.T @ lam) * sq
            gfull = ga + Bm.T @ lam
            ra = a - np.clip(a - gfull, 0.0, 1.0)
            gscale = 1.0 + max(np.abs(gq * sq).max(), np.abs(ga).max())
            stat = max(np.abs(rq).max(), np.abs(ra).max()) / gscale
            qres = np.abs(st["Q"][i] * self.qscale).max() / (1.0 + np.abs(Fs).max())
            out[k] = max(stat, qres)
        return out

    def _kkt_ok(self, st, i):
        """Stopping test: the KKT residual of scenario i is below half the certification tolerance (margin
        for the final polish)."""
        return bool(self.kkt_residuals(st, [i])[0] <= 0.5 * self.kkt_tol)

    # ------------------------------------------------------------------ driver
    def solve(self, target_flexion_deg, params, x0=None, R0=None, a0=None) -> PostureSolution:
        """One posture (``params`` for a batch of one; see :meth:`solve_batch`)."""
        p = {k: (v[None] if k in ("force_vec", "force_pt", "prop_stack") and np.ndim(v) == 2 else v)
             for k, v in params.items()}
        return self.solve_batch([target_flexion_deg], p, None if x0 is None else np.asarray(x0)[None],
                                None if R0 is None else np.asarray(R0)[None],
                                None if a0 is None else np.asarray(a0)[None])[0]

    def solve_batch(self, targets_deg, params, x0=None, R0=None, a0=None) -> list:
        """Solve B postures together (:meth:`_solve_batch`). A scenario whose line search failed away from
        equilibrium (no equilibrium found) is solved once more from the same start with the step lengths
        extended down to ``retry_line_search`` (the close crate with the OpenSim 4.6 active curve stalled at a
        30 N residual with the short search, and is certified with the long one)."""
        from ..mechanics import profile  # noqa: PLC0415
        profile.count("muscle_postures", len(np.atleast_1d(targets_deg)))
        with profile.phase("muscle_solve"):
            return self._solve_batch_certified(targets_deg, params, x0, R0, a0)

    def _solve_batch_certified(self, targets_deg, params, x0=None, R0=None, a0=None) -> list:
        out = self._solve_batch(targets_deg, params, x0, R0, a0)
        B = len(out)
        out = self._retry(out, B, targets_deg, params, x0, R0, a0)
        if self.certifier is not None:
            targets = np.asarray(targets_deg, float).reshape(-1)
            self._certify(out, targets, params)
            if self.multistart and x0 is None:
                self._multistart(out, targets, params)
        return out

    def _multistart(self, out, targets, params):
        """Second start for cold solves: IPOPT alone from the same start pose (thorax rotation spread over the
        levels, zero activations). Both are local methods; where IPOPT reaches a certified optimum of lower cost
        (e.g. 19 deg extension: cost 2.896 vs the SQP's 3.038, benchmarks/bench_muscle_solvers.py), it replaces
        the SQP's. ``optimum`` names the path that gave the reported optimum, ``other_cost`` the other path's
        cost (NaN if it did not reach a certified optimum)."""
        B = len(out)
        t0 = time.perf_counter()
        for i, o in enumerate(out):
            if i:
                el = time.perf_counter() - t0
                log.info("multistart (IPOPT from the cold start): %d / %d postures done, %.0f s elapsed, ~%.0f s "
                         "remaining", i, B, el, el / i * (B - i))
            p = {k: (v[i:i + 1] if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == B else v)
                 for k, v in params.items()}
            x0, R0 = self.initial_pose(targets[i])
            r = self.certifier.solve(targets[i], p, x0, R0, np.zeros(self.m.ms.n), warm=False,
                                     max_iter=self.multistart_max_iter)
            st = self.evaluate_state(r.x[None], r.R[None], r.a[None], p, [targets[i]])
            terr = float(np.linalg.norm(st["e"][0]))
            cost = float(st["c"][0])
            ok = r.success and r.equilibrium_residual < 1e-6 and terr <= self.max_tracking_deg
            if ok and (not o.certified or cost < o.cost - 1e-6 * (1.0 + abs(o.cost))):
                log.info("posture %d (target %.1f deg): IPOPT from the cold start found a certified optimum of "
                         "cost %.6g (SQP path: %.6g, certified %s); it is reported", i, targets[i], cost, o.cost,
                         o.certified)
                Q = st["Q"][0].reshape(-1, 6)
                o.other_cost = o.cost if o.certified else float("nan")
                o.x, o.R, o.a, o.cost, o.tracking_error_deg = r.x, r.R, r.a, cost, terr
                o.residual_force_n = float(np.abs(Q[:, :3]).max())
                o.residual_moment_nm = float(np.abs(Q[:, 3:]).max())
                o.equilibrium = o.reached = o.certified = True
                o.kkt_residual, o.ipopt_status, o.optimum = r.kkt_residual, r.status, "ipopt_cold"
                o.iterations += r.iterations
                o.message = ""
                o.converged = True
            else:
                o.other_cost = cost if ok else float("nan")

    def _certify(self, out, targets, params):
        """IPOPT (:mod:`lumbar.muscles.nlp`) certifies every reached posture: its convergence test at the
        SQP's optimum; where that fails, IPOPT iterates from there (exact gradients, Hessian by differences of
        them) and its optimum replaces the SQP's if it is reached. ``kkt_residual`` is IPOPT's final NLP
        error; ``sqp_kkt_residual`` is the SQP's own measure at the reported point. Unreached postures get IPOPT's error at the
        returned point (no certificate)."""
        B = len(out)
        t0 = time.perf_counter()
        for i, o in enumerate(out):
            if i and i % 16 == 0:
                el = time.perf_counter() - t0
                log.info("IPOPT certificate: %d / %d postures done, %.0f s elapsed, ~%.0f s remaining", i, B, el,
                         el / i * (B - i))
            p = {k: (v[i:i + 1] if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == B else v)
                 for k, v in params.items()}
            o.sqp_kkt_residual = o.kkt_residual
            chk = self.certifier.certify(targets[i], p, o.x, o.R, o.a)
            o.kkt_residual, o.ipopt_status = chk.kkt_residual, chk.status
            if not o.reached:
                o.certified = o.converged = False
                continue
            if chk.success:
                o.certified = True
            else:
                r = self.certifier.solve(targets[i], p, o.x, o.R, o.a, warm=self.polish_start)
                st = self.evaluate_state(r.x[None], r.R[None], r.a[None], p, [targets[i]])
                terr = float(np.linalg.norm(st["e"][0]))
                eq = r.equilibrium_residual < 1e-6
                if r.success and eq and terr <= self.max_tracking_deg:
                    log.info("posture %d (target %.1f deg): IPOPT moved the SQP point (KKT %.1e, cost %.6g) to a "
                             "certified optimum in %d iterations (KKT %.1e, cost %.6g)", i, targets[i],
                             chk.kkt_residual, o.cost, r.iterations, r.kkt_residual, r.cost)
                    Q = st["Q"][0].reshape(-1, 6)
                    o.x, o.R, o.a = r.x, r.R, r.a
                    o.cost, o.tracking_error_deg = float(st["c"][0]), terr
                    o.residual_force_n = float(np.abs(Q[:, :3]).max())
                    o.residual_moment_nm = float(np.abs(Q[:, 3:]).max())
                    o.iterations += r.iterations
                    o.certified, o.kkt_residual, o.ipopt_status = True, r.kkt_residual, r.status
                    o.sqp_kkt_residual = float(self.kkt_residuals(st)[0])   # the SQP's measure at the reported point
                else:
                    o.certified = False
                    o.ipopt_status = r.status
            if o.certified:
                o.message = ""
            else:
                o.message = (f"IPOPT: KKT residual {o.kkt_residual:.1e} > {self.certifier.tol:.0e} ({o.ipopt_status}): "
                             "optimum not certified")
                # recorded (certified, ipopt_status, message); the workflow's rule warns once with the count
                log.info("posture %d (target %.1f deg) reached but not certified: %s", i, targets[i], o.message)
            o.converged = bool(o.reached and (o.certified or self.accept_suboptimal))

    def _retry(self, out, B, targets_deg, params, x0, R0, a0):
        redo = [i for i, o in enumerate(out) if not o.equilibrium and "line search failed" in o.message]
        if redo and self.retry_line_search:
            idx = np.array(redo)
            sub = {k: (v[idx] if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == B else v)
                   for k, v in params.items()}
            keep = self.line_search
            self.line_search = self.retry_line_search
            try:
                again = self._solve_batch(np.asarray(targets_deg, float).reshape(-1)[idx], sub,
                                          None if x0 is None else np.asarray(x0)[idx],
                                          None if R0 is None else np.asarray(R0)[idx],
                                          None if a0 is None else np.asarray(a0)[idx])
            finally:
                self.line_search = keep
            for i, o in zip(redo, again):
                log.info("posture %d retried with the longer line search: reached %s, certified %s (was: %s)", i,
                         o.reached, o.certified, out[i].message)
                o.iterations += out[i].iterations
                out[i] = o
        return out

    def _solve_batch(self, targets_deg, params, x0=None, R0=None, a0=None) -> list:
        """Solve B postures together. ``params``: per-scenario arrays (leading B) ``force_vec``,
        ``force_pt`` (from ``model.load_arrays``) and optionally ``prop_stack`` (``model.props_stack``), or
        shared ``props`` / ``forces``. Start: ``x0, R0, a0`` (e.g. the baseline solution) or the reference
        pose with the target spread over the levels and zero activations. Steps: :meth:`_start`, phase 0 (the
        thorax held) and phase 1 (:meth:`_iterate`), :meth:`_polish`, :meth:`_solutions`."""
        b = self._start(targets_deg, params, x0, R0, a0)
        for _ in range(self.phase0_iter if a0 is None else 0):
            act = np.flatnonzero(~b.stop)
            if act.size == 0:
                break
            self._iterate(b, True, act)
        for _ in range(self.max_iter):
            act = np.flatnonzero(~b.done)
            if act.size == 0:
                break
            self._iterate(b, False, act)
            if self.handover_window and self.certifier is not None:
                self._handover(b, act)
        self._polish(b)
        return self._solutions(b)

    def _handover(self, b: _Batch, act):
        """Stop the reached scenarios of ``act`` whose cost stalled (see ``handover_window``); IPOPT takes over."""
        st, w = b.st, self.handover_window
        terr = np.linalg.norm(st["e"][act], axis=-1)
        resid = np.abs(st["Q"][act]).max(-1)
        for k, i in enumerate(act):
            h = b.costs[i]
            h.append(float(st["c"][i]))
            if b.done[i] or len(h) <= w or resid[k] >= self.tol or terr[k] > self.max_tracking_deg:
                continue
            if h[-1 - w] - h[-1] < self.handover_rel * (1.0 + abs(h[-1])):
                b.done[i] = True
                b.msg[i] = (f"handed to IPOPT: reached, cost down by < {self.handover_rel:g} (relative) over "
                            f"{w} SQP iterations")

    def _start(self, targets_deg, params, x0, R0, a0) -> _Batch:
        """The batch's start: poses, activations and state; for a cold start with targets beyond
        ``start_min_deg``, the free vertebrae first in equilibrium with the thorax held."""
        m = self.m
        targets = np.asarray(targets_deg, float).reshape(-1)
        B = self._B = len(targets)
        nm = m.ms.n
        if x0 is None:
            xs = [self.initial_pose(t) for t in targets]
            x0 = np.stack([s[0] for s in xs])
            R0 = np.stack([s[1] for s in xs])
        x, R = np.array(x0, float), np.array(R0, float)
        a = np.zeros((B, nm)) if a0 is None else np.clip(np.array(a0, float), 0.0, 1.0)
        allidx = np.arange(B)
        far = np.flatnonzero(np.abs(targets) > self.start_min_deg) if (x0 is None or a0 is None) else []
        if len(far) and self.start_iter:   # start: free vertebrae in equilibrium, thorax held
            p = {k: (v[far] if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == B else v)
                 for k, v in params.items()}
            p["activation"] = a[far]
            res = solve(_ThoraxHeld(m), np.zeros((len(far), m.nb, 6)), x0=x[far], R0=R[far], params=p,
                        max_iter=self.start_iter, tol_force=1e-6, tol_moment=1e-6, retry_load_steps=())
            x[far], R[far] = res.x, res.R
        st = self._state(x, R, a, params, allidx, targets)
        return _Batch(x, R, a, st, params, targets, D=np.full(B, self.trust0), mu=np.full(B, self.mu0),
                      done=np.zeros(B, bool), optimal=np.zeros(B, bool), stop=np.zeros(B, bool),
                      iters=np.zeros(B, int), warm=[None] * B, msg=[""] * B, costs=[[] for _ in range(B)])

    def _iterate(self, b: _Batch, held, act):
        """One SQP iteration of the scenarios ``act``: QP steps, capped, then the line search and its acceptance
        (``held``: phase 0, the thorax rotation held at its target)."""
        dq, da, pred, predc, skip = self._qp_steps(b, held, act)
        cap = np.maximum(np.abs(dq[..., :3]).max((-1, -2)) / self.max_step_m,
                         np.abs(dq[..., 3:]).max((-1, -2)) / self.max_step_rad)
        fac = 1.0 / np.maximum(1.0, cap)
        dq *= fac[:, None, None]
        da *= fac[:, None]
        pred *= fac
        b.iters[act] += 1
        m_old = self._merit({k: v[act] for k, v in b.st.items()}, b.mu[act], held)
        tr = self._line_search(b, held, act, dq, da, pred, skip, m_old)
        self._accept(b, held, act, dq, da, pred, predc, skip, m_old, tr)

    def _qp_steps(self, b: _Batch, held, act):
        """The QP step of every scenario of ``act`` (:meth:`_qp`): pose and activation steps, predicted merit and
        cost decreases, and which scenarios are already stationary (``skip``: done, the polish follows)."""
        m, st = self.m, b.st
        dq = np.zeros((act.size, m.nb, 6))
        da = np.zeros((act.size, m.ms.n))
        pred = np.zeros(act.size)
        predc = np.zeros(act.size)
        skip = np.zeros(act.size, bool)
        for k, i in enumerate(act):
            out = self._qp(st, i, b.a[i], b.D[i], b.warm[i], b.mu[i], held)
            if out is None:          # QP failed: shrink and retry next iteration
                b.D[i] *= 0.25
                continue
            dqk, da[k], pred[k], b.warm[i] = out
            predc[k] = self._pred_cost
            dq[k] = dqk.reshape(m.nb, 6)
            if not held and np.abs(st["Q"][i]).max() < self.polish_from and (
                    abs(predc[k]) < self.rel_cost_tol * (1.0 + st["c"][i]) or self._kkt_ok(st, i)):
                b.done[i] = b.optimal[i] = True      # stationary: the polish below restores equilibrium
                skip[k] = True
        return dq, da, pred, predc, skip

    def _line_search(self, b: _Batch, held, act, dq, da, pred, skip, m_old) -> _Trials:
        """The trial points of the line search and their merit. The full step first, for every scenario at once;
        the shorter steps only where it fails the Armijo test (about a quarter of the steps; evaluating all of them
        in one batch cost six trial evaluations per iteration). The step chosen is the same as with all of them."""
        m, ts = self.m, self.line_search
        nt = len(ts)
        tr = _Trials(m_new=np.full((act.size, nt), np.inf), xn=np.zeros((act.size * nt, m.nb, 3)),
                     Rn=np.zeros((act.size * nt, m.nb, 3, 3)), an=np.zeros((act.size * nt, m.ms.n)), sn={})
        first = np.flatnonzero(~skip)
        if first.size and not self.full_step_first:        # the former search: all step lengths at once
            self._trial(b, held, act, dq, da, tr, first, np.arange(nt))
        elif first.size:
            self._trial(b, held, act, dq, da, tr, first, np.arange(1))
            full = tr.m_new[first, 0] <= m_old[first] - 1e-4 * ts[0] * np.maximum(pred[first], 0.0)
            rest = first[~full]
            if rest.size and nt > 1:
                self._trial(b, held, act, dq, da, tr, rest, np.arange(1, nt))
        return tr

    def _trial(self, b: _Batch, held, act, dq, da, tr: _Trials, rows, cols):
        """Trial points of step lengths ``cols`` for scenarios ``rows`` (of ``act``), each first restored to
        equilibrium (phase 1), into ``tr``."""
        nt = len(self.line_search)
        kk, jj = np.repeat(rows, len(cols)), np.tile(cols, len(rows))
        r, tt = kk * nt + jj, np.asarray(self.line_search)[jj]
        tr.an[r] = b.a[act][kk] + tt[:, None] * da[kk]
        dqt = tt[:, None, None] * dq[kk]
        xt, Rt = b.x[act][kk] + dqt[..., :3], so3.exp(dqt[..., 3:]) @ b.R[act][kk]
        if not held and self.restore_iter:
            xt, Rt, s_t = self._restored_state(xt, Rt, tr.an[r], b.params, act[kk], b.targets[act][kk])
        else:
            s_t = self._state(xt, Rt, tr.an[r], b.params, act[kk], b.targets[act][kk])
        tr.xn[r], tr.Rn[r] = xt, Rt
        for key, v in s_t.items():
            if key not in tr.sn:
                tr.sn[key] = np.zeros((act.size * nt,) + v.shape[1:], v.dtype)
            tr.sn[key][r] = v
        tr.m_new[kk, jj] = self._merit(s_t, b.mu[act][kk], held)

    def _accept(self, b: _Batch, held, act, dq, da, pred, predc, skip, m_old, tr: _Trials):
        """Per scenario: the first step length that passes the Armijo test (else the lowest merit below the old
        one), the stopping tests, or, where no step decreases the merit away from equilibrium, a raised merit
        weight."""
        ts, nt, st = self.line_search, len(self.line_search), b.st
        for k, i in enumerate(act):
            if skip[k]:
                continue
            ok = tr.m_new[k] <= m_old[k] - 1e-4 * np.asarray(ts) * max(pred[k], 0.0)
            if ok.any():
                j = int(np.argmax(ok))
            elif tr.m_new[k].min() < m_old[k]:
                j = int(np.argmin(tr.m_new[k]))
            else:
                j = -1
            resid = np.abs(st["Q"][i]).max()
            if j >= 0:
                r = k * nt + j
                b.x[i], b.R[i], b.a[i] = tr.xn[r], tr.Rn[r], tr.an[r]
                for key in st:
                    st[key][i] = tr.sn[key][r]
                stepa = ts[j] * np.abs(da[k]).max()
                stepq = ts[j] * np.abs(dq[k]).max()
                resid = np.abs(st["Q"][i]).max()
                if not held and resid < self.tol:
                    # back at equilibrium: a merit weight raised far from it would let the restored
                    # trials' round-off residual (mu * |Q|_1) outweigh small true cost decreases
                    b.mu[i] = self.mu0
                if held:
                    mom = np.abs(st["Q"][i][self.rot]).max()
                    if stepa < 10 * self.step_tol and mom < 1e-2:
                        b.stop[i] = True
                elif resid < self.tol and ((stepa < self.step_tol and stepq < 1e-6)
                                           or pred[k] < 1e-9 * (1.0 + st["c"][i]) or self._kkt_ok(st, i)):
                    b.done[i] = b.optimal[i] = True
            elif np.abs(self._qres(st, i, held)).max() >= self.tol and b.mu[i] < self.mu_max:
                # away from equilibrium the SQP step (which satisfies the linearised equilibrium) is a
                # descent direction of the L1 merit only if mu exceeds the equilibrium multipliers;
                # raise it and retry from the same point (a tenfold step per failed search)
                b.mu[i] *= 10.0
            elif held:
                b.stop[i] = True
            else:
                b.done[i] = True
                # at equilibrium: stationary if the QP's predicted cost decrease is below the same
                # relative tolerance as the regular stop (pred also holds mu |Q|_1, inflated by a raised mu)
                if resid < self.tol and (pred[k] < 1e-8 * (1.0 + st["c"][i])
                                         or abs(predc[k]) < self.rel_cost_tol * (1.0 + st["c"][i])):
                    b.optimal[i] = True
                else:
                    b.msg[i] = "line search failed (no decrease of the merit function)"

    def _polish(self, b: _Batch):
        """Newton on the poses with the activations fixed (equilibrium to tol). Steps are capped at twice the
        SQP's pose step limits and kept only where they lower the residual, so a posture the SQP left off the
        equilibrium manifold (line search failed after a rejected trial) is brought back onto it; whether its
        thorax is then on target decides ``reached``."""
        m, st = self.m, b.st
        for _ in range(40):
            bad = np.flatnonzero(np.abs(st["Q"]).max(-1) >= self.tol)
            if bad.size == 0:
                break
            d = -np.linalg.solve(st["J"][bad], st["Q"][bad][..., None])[..., 0].reshape(-1, m.nb, 6)
            cap = np.maximum(np.abs(d[..., :3]).max((-1, -2)) / (2 * self.max_step_m),
                             np.abs(d[..., 3:]).max((-1, -2)) / (2 * self.max_step_rad))
            d /= np.maximum(cap, 1.0)[:, None, None]
            xt = b.x[bad] + d[..., :3]
            Rt = so3.exp(d[..., 3:]) @ b.R[bad]
            sb = self._state(xt, Rt, b.a[bad], b.params, bad, b.targets[bad])
            better = np.abs(sb["Q"]).max(-1) < np.abs(st["Q"][bad]).max(-1)
            if not better.any():
                break
            keep = bad[better]
            b.x[keep], b.R[keep] = xt[better], Rt[better]
            for key in st:
                st[key][keep] = sb[key][better]

    def _solutions(self, b: _Batch) -> list:
        """The batch's :class:`PostureSolution` list: equilibrium, reached, certified, converged and the message."""
        m, st, msg, targets = self.m, b.st, b.msg, b.targets
        B = len(targets)
        out = []
        Q = st["Q"].reshape(B, m.nb, 6)
        rf = np.abs(Q[..., :3]).max((-1, -2))
        rm = np.abs(Q[..., 3:]).max((-1, -2))
        terr = np.linalg.norm(st["e"], axis=-1)
        kkt = self.kkt_residuals(st)
        for i in range(B):
            eq = bool(rf[i] < 1e-6 and rm[i] < 1e-6)
            reached = bool(eq and terr[i] <= self.max_tracking_deg)
            certified = bool(reached and kkt[i] <= self.kkt_tol)
            if not b.optimal[i] and not msg[i]:
                msg[i] = f"SQP stopped after {self.max_iter} iterations without meeting its tolerances"
            if not eq:
                msg[i] = msg[i] or "no equilibrium"
            if terr[i] > self.max_tracking_deg:
                miss = (f"thorax misses its target by {terr[i]:.2f} deg (> {self.max_tracking_deg} deg): "
                        "the muscles cannot hold this posture")
                msg[i] = f"{miss}; {msg[i]}" if msg[i] else miss
            if reached and not certified:
                cert = f"KKT residual {kkt[i]:.1e} > {self.kkt_tol:.0e}: optimum not certified"
                msg[i] = f"{cert}; {msg[i]}" if msg[i] else cert
            elif certified:
                msg[i] = ""          # the KKT certificate decides, whatever stopped the SQP
            # converged = reached with a certified optimum (the KKT residual, not the SQP's stopping rule)
            conv = bool(reached and (certified or self.accept_suboptimal))
            if not conv:
                # an outcome of this posture, recorded in its solution (reached, converged, message) and in the
                # workflow's tables (red stars), with one summary line per rule: a progress note, not a warning
                log.info("posture %d (target %.1f deg) not converged by the SQP: %s (residual %.1e N, %.1e N*m, "
                         "tracking error %.2f deg, KKT residual %.1e)", i, targets[i], msg[i], rf[i], rm[i],
                         terr[i], kkt[i])
            out.append(PostureSolution(b.x[i].copy(), b.R[i].copy(), b.a[i].copy(), conv, eq, float(terr[i]),
                                       float(rf[i]), float(rm[i]), float(st["c"][i]), int(b.iters[i]), msg[i],
                                       reached, float(kkt[i]), certified))
        return out


    def initial_pose(self, theta_deg):
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
