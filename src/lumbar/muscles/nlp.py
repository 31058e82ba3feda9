"""The posture problem as a nonlinear program solved by IPOPT (through CasADi), with the model's exact first
derivatives: the certifier of every reported muscle-model optimum.

Problem (the same as :mod:`lumbar.muscles.redundancy`, one posture)::

    minimise   w_a |a|^2 + w_f sum_levels |F_level(q)|^2 + w_t |thorax rotation(q) - target|_deg^2
    subject to Q(q, a) = 0 (static equilibrium of every free body, N and N*m / length_scale_m),  0 <= a <= 1

Variables: the activations ``a`` and the pose increments of the free bodies from a start pose
``(x0, R0)``: ``x = x0 + 1e-3 u_x`` (mm) and ``R = exp(1e-2 u_r) R0`` (10 mrad), the same scaling as the SQP's
pose variables. The model gives derivatives with respect to a spatial (left) rotation increment ``delta``; by
the chain rule ``d/du_r = d/ddelta * J_l(phi)`` with ``J_l`` the left Jacobian of SO(3) (:func:`so3.left_jacobian`).

The NLP is built from a CasADi :class:`casadi.Callback` that evaluates cost and constraints in numpy and
provides their exact Jacobian (another callback); IPOPT (bundled with the ``casadi`` wheel, linear solver MUMPS)
approximates the Hessian of the Lagrangian by limited-memory BFGS (the model's second derivatives are not
available). IPOPT's own stopping test is the certificate: a posture is ``certified`` when IPOPT reports
``Solve_Succeeded`` (scaled NLP error <= ``tol``, equilibrium residual <= ``constr_viol_tol``), and the
reported ``kkt_residual`` is IPOPT's final NLP error (the largest of its scaled dual infeasibility, primal
infeasibility and complementarity). The maintained solver, not the project's stopping rule, decides.

Used as a polish of the SQP's optimum (:meth:`RedundancySolver.solve_batch` with ``certifier``): IPOPT starts
there with a small barrier parameter (``mu_init``), so a true optimum costs a few iterations and an SQP point
that was not optimal is moved to one. It also runs stand-alone from the reference pose
(``benchmarks/bench_muscle_model.py`` compares both paths).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..mechanics import so3

log = logging.getLogger(__name__)

POSE_SCALE = np.r_[np.full(3, 1e-3), np.full(3, 1e-2)]   # m and rad per NLP pose unit (mm, 10 mrad)


#: an activation within this of 0 or 1 is at its bound (IPOPT's interior-point optima leave 1e-10..1e-8 there; a
#: least-squares multiplier that treated them as free would fail a certificate at IPOPT's own optimum)
BOUND_TOL = 1e-6


@dataclass
class NLPResult:
    x: np.ndarray            # (nb, 3)
    R: np.ndarray            # (nb, 3, 3)
    a: np.ndarray            # (nm,)
    success: bool            # IPOPT: Solve_Succeeded (or Solved_To_Acceptable_Level if accept_acceptable)
    status: str              # IPOPT return status
    kkt_residual: float      # IPOPT's final scaled NLP error
    cost: float
    iterations: int
    equilibrium_residual: float   # max |Q| [N, N*m] at the returned point


class _Problem:
    """Cost, constraints and exact Jacobians of one posture at the NLP variables z = (u (6 nb), a (nm)),
    evaluated by the solver's model (one cached evaluation per distinct z)."""

    def __init__(self, solver):
        self.s, self.m = solver, solver.m
        self.nb, self.nm = self.m.nb, self.m.ms.n
        self.n = 6 * self.nb
        self.n_eval = 0
        self.fd_step = 1e-6          # NLP pose units (1 nm, 10 nrad): finite differences of the exact gradient

    def reset(self, params, target_deg, x0, R0):
        """The scenario: per-scenario ``params`` (batch of one), thorax target [deg], start pose."""
        self.params, self.target = params, float(target_deg)
        self.x0, self.R0 = np.asarray(x0, float), np.asarray(R0, float)
        self._key, self._val = None, None

    def hessian(self, z, lam_f, lam_g):
        """Hessian of the Lagrangian ``lam_f f + lam_g^T g``: columns along the pose variables by forward
        differences of its exact gradient (``grad f``, ``Jg``); the activations enter the cost quadratically
        (``2 w_a``) and the constraints linearly, so their block is exact. Symmetrised."""
        z = np.asarray(z, float).reshape(-1)
        lam_g = np.asarray(lam_g, float).reshape(-1)
        n = self.n

        Z = np.repeat(z[None], n + 1, 0)
        Z[np.arange(1, n + 1), np.arange(n)] += self.fd_step       # row 0: z; row i: z + h e_(i-1)
        _, _, grad, Jg, _, _ = self.evaluate_batch(Z)
        gl = lam_f * grad + np.einsum("kgz,g->kz", Jg, lam_g)
        H = np.zeros((z.size, z.size))
        H[:, :n] = ((gl[1:] - gl[0]) / self.fd_step).T
        H[n:, n:] = 2.0 * lam_f * self.s.w.activation * np.eye(self.nm)
        H[:n, n:] = H[n:, :n].T
        return 0.5 * (H + H.T)

    def pose(self, z):
        u = z[: self.n].reshape(self.nb, 6) * POSE_SCALE
        return self.x0 + u[:, :3], so3.exp(u[:, 3:]) @ self.R0, u[:, 3:]

    def evaluate(self, z):
        """(cost, g, grad f, Jg, x, R) at z (cached for the last z)."""
        z = np.asarray(z, float).reshape(-1)
        key = z.tobytes()
        if key != self._key:
            self.n_eval += 1
            self._key, self._val = key, tuple(v[0] for v in self.evaluate_batch(z[None]))
        return self._val

    def evaluate_batch(self, Z):
        """Cost (K,), constraints (K, n), cost gradient (K, nz), constraint Jacobian (K, n, nz) and the poses
        at the K points ``Z`` (one vectorised model evaluation)."""
        Z = np.asarray(Z, float)
        K, n, s, w = len(Z), self.n, self.s, self.s.w
        u = Z[:, :n].reshape(K, self.nb, 6) * POSE_SCALE
        x = self.x0 + u[..., :3]
        R = so3.exp(u[..., 3:]) @ self.R0
        a = Z[:, n:]
        params = {k: (np.repeat(v, K, 0) if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == 1 else v)
                  for k, v in self.params.items()}
        st = s.evaluate_state(x, R, a, params, np.full(K, self.target))
        Fs = (st["FL"] * s.fscale).reshape(K, -1)
        DLs = (st["DL"] * s.fscale[None, None, :, None, None]).reshape(K, -1, n)
        gq = 2.0 * w.fsu_load_per_n2 * np.einsum("kri,kr->ki", DLs, Fs)
        gq[:, s.rot] += 2.0 * w.tracking_per_deg2 * np.einsum("kij,ki->kj", st["Te"], st["e"])
        # chain rule: pose variables u -> (translation, spatial rotation increment delta): block diagonal T
        T = np.zeros((K, self.nb, 6, self.nb, 6))
        Jl = so3.left_jacobian(u[..., 3:]) * POSE_SCALE[3]
        for b in range(self.nb):
            T[:, b, :3, b, :3] = np.eye(3) * POSE_SCALE[0]
            T[:, b, 3:, b, 3:] = Jl[:, b]
        T = T.reshape(K, n, n)
        qs = s.qscale
        g = st["Q"] * qs
        Jg = np.concatenate([(st["J"] * qs[:, None]) @ T, st["Bm"] * qs[:, None]], axis=2)
        grad = np.concatenate([np.einsum("ki,kij->kj", gq, T), 2.0 * w.activation * a], axis=1)
        return st["c"], g, grad, Jg, x, R


class _Callback(ca.Callback):
    """A CasADi callback over the posture problem, its inputs and outputs given as sparsity lists (CasADi asks
    for their number and each one's sparsity through the get_* methods)."""

    def __init__(self, prob, name, ins, outs, opts=None):
        ca.Callback.__init__(self)
        self.p, self.nz = prob, prob.n + prob.nm
        self._ins, self._outs = ins, outs
        self.construct(name, opts or {})

    def get_n_in(self):
        return len(self._ins)

    def get_n_out(self):
        return len(self._outs)

    def get_sparsity_in(self, i):
        return self._ins[i]

    def get_sparsity_out(self, i):
        return self._outs[i]


def _dense(rows, cols=1):
    return ca.Sparsity.dense(rows, cols)


class _FG(_Callback):
    """Cost f and constraints g at z, with the exact Jacobian (:class:`_Jac`)."""

    def __init__(self, prob, name="posture_fg"):
        nz = prob.n + prob.nm
        super().__init__(prob, name, [_dense(nz)], [_dense(1), _dense(prob.n)], {"enable_fd": False})

    def eval(self, arg):
        f, g = self.p.evaluate(np.asarray(arg[0]))[:2]
        return [f, g]

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _Jac(self.p, name)
        return self._jac


class _Jac(_Callback):
    """Jacobian of (f, g): inputs (z, f, g) (CasADi passes the nominal outputs too), outputs df/dz, dg/dz."""

    def __init__(self, prob, name):
        nz = prob.n + prob.nm
        super().__init__(prob, name, [_dense(nz), _dense(1), _dense(prob.n)], [_dense(1, nz), _dense(prob.n, nz)])

    def eval(self, arg):
        _, _, grad, Jg = self.p.evaluate(np.asarray(arg[0]))[:4]
        return [grad[None, :], Jg]


class _Hess(_Callback):
    """Hessian of the Lagrangian for IPOPT (nlpsol option ``hess_lag``): inputs (z, p, lam_f, lam_g), output
    its upper triangle (dense)."""

    def __init__(self, prob, name="posture_hess"):
        nz = prob.n + prob.nm
        self._upper = ca.Sparsity.upper(nz)
        self._rows, self._cols = (np.asarray(v, int) for v in self._upper.get_triplet())   # its nonzeros, in order
        super().__init__(prob, name, [_dense(nz), _dense(0), _dense(1), _dense(prob.n)], [self._upper])

    def eval(self, arg):
        H = self.p.hessian(np.asarray(arg[0]), float(arg[2]), np.asarray(arg[3]))
        # the upper triangle's nonzeros straight from the array (a dense DM of H, then triu, was 3 ms a call)
        return [ca.DM(self._upper, H[self._rows, self._cols])]


class IpoptPostureSolver:
    """IPOPT on the posture NLP (module docstring). ``solver``: the :class:`RedundancySolver` whose model,
    weights, scaling and tracking definition are used (one problem definition for both paths).

    :meth:`certify` evaluates IPOPT's convergence test at a given point (``max_iter`` 0: IPOPT's own
    optimality error with least-squares multipliers; no step is taken); :meth:`solve` runs IPOPT with the
    Hessian of the Lagrangian from :meth:`_Problem.hessian`.

    ``tol`` [cost units per NLP variable unit: per mm, per 10 mrad, per unit activation; the posture costs are
    1-30] is IPOPT's overall NLP error at which an optimum is certified; ``constr_viol_tol`` [N, and N*m per
    ``length_scale_m``] the equilibrium residual."""

    def __init__(self, solver, tol=1e-5, constr_viol_tol=1e-6, max_iter=50, mu_init=1e-8, pose_bound=50.0):
        if not (tol > 0 and constr_viol_tol > 0):
            raise ValueError(f"IPOPT tolerances must be > 0, got tol {tol}, constr_viol_tol {constr_viol_tol}")
        self.s = solver
        self.tol, self.constr_viol_tol, self.max_iter = float(tol), float(constr_viol_tol), int(max_iter)
        self.mu_init = float(mu_init)
        self.pose_bound = float(pose_bound)     # |u| <= 50 mm, 0.5 rad from the start pose
        self.prob = _Problem(solver)
        self._nlp = {}

    def options(self, max_iter, warm=True):
        """IPOPT options. ``warm``: True or "dual" (the primal start and the least-squares multipliers of
        :meth:`multipliers`, IPOPT's ``warm_start_init_point``; the certificate), "primal" (the primal start
        with a small barrier parameter and bound push, multipliers from IPOPT's own initialisation; the polish of
        an SQP point that failed the certificate: with the warm multipliers IPOPT's first step from such a
        point was typically rejected by twelve backtracking steps, measured on 39 Sobol samples: 648 model
        evaluations vs 306, 38 vs 39 certified) or False (a cold start)."""
        o = {"tol": self.tol, "constr_viol_tol": self.constr_viol_tol, "dual_inf_tol": self.tol,
             "compl_inf_tol": self.tol, "max_iter": int(max_iter), "print_level": 0, "sb": "yes",
             "acceptable_iter": 0, "nlp_scaling_method": "none"}
        if warm == "primal":
            o |= {"mu_init": self.mu_init, "bound_push": 1e-12, "bound_frac": 1e-12, "slack_bound_push": 1e-12,
                  "slack_bound_frac": 1e-12}
        elif warm:
            o |= {"mu_init": self.mu_init, "warm_start_init_point": "yes", "warm_start_bound_push": 1e-12,
                  "warm_start_bound_frac": 1e-12, "warm_start_slack_bound_push": 1e-12,
                  "warm_start_slack_bound_frac": 1e-12, "warm_start_mult_bound_push": 1e-12}
        return {"ipopt": o, "print_time": False, "verbose_init": False}

    def _solver(self, max_iter, warm=True):
        key = (int(max_iter), "dual" if warm is True else warm)
        if key not in self._nlp:
            prob = self.prob
            fg = _FG(prob)
            z = ca.MX.sym("z", prob.n + prob.nm)
            f, g = fg(z)
            opts = self.options(max_iter, warm)
            if not hasattr(self, "_hess"):
                self._hess = _Hess(prob)
            opts["hess_lag"] = self._hess       # not called when max_iter is 0
            self._nlp[key] = (ca.nlpsol(f"posture_{max_iter}", "ipopt", {"x": z, "f": f, "g": g}, opts), fg)
        return self._nlp[key][0]

    def certify(self, target_deg, params, x, R, a) -> NLPResult:
        """IPOPT's convergence test at the posture ``(x, R, a)`` (no iteration)."""
        return self._run(0, target_deg, params, x, R, a, True)

    def solve(self, target_deg, params, x0, R0, a0, warm=True, max_iter=None) -> NLPResult:
        """IPOPT from the start ``(x0, R0, a0)`` (``params``: the per-scenario parameters of a batch of one, as
        for :meth:`RedundancySolver.solve`); ``warm``: a start near an optimum, with least-squares multipliers
        (True, "dual") or with IPOPT's own multipliers ("primal"), both with a small barrier parameter
        (:meth:`options`)."""
        return self._run(self.max_iter if max_iter is None else max_iter, target_deg, params, x0, R0, a0, warm)

    def _run(self, max_iter, target_deg, params, x0, R0, a0, warm):
        prob = self.prob
        nlp = self._solver(max_iter, warm)
        prob.reset(params, target_deg, x0, R0)
        lbx = np.r_[np.full(prob.n, -self.pose_bound), np.zeros(prob.nm)]
        ubx = np.r_[np.full(prob.n, self.pose_bound), np.ones(prob.nm)]
        zinit = np.r_[np.zeros(prob.n), np.clip(np.asarray(a0, float), 0.0, 1.0)]
        kw = {}
        if warm and warm != "primal":
            lam_g, lam_x = self.multipliers(zinit)
            kw = {"lam_g0": lam_g, "lam_x0": lam_x}
        sol = nlp(x0=zinit, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0, **kw)
        st = nlp.stats()
        zs = np.asarray(sol["x"]).reshape(-1)
        c, gval, _, _, x, R = prob.evaluate(zs)
        it = st.get("iterations", {})
        err = np.nan
        if it:
            err = float(max(it["inf_du"][-1], it["inf_pr"][-1]))
        status = str(st.get("return_status", ""))
        resid = float(np.abs(gval / self.s.qscale).max())
        return NLPResult(x, R, zs[prob.n:].copy(), status == "Solve_Succeeded", status, err, c,
                         int(st.get("iter_count", -1)), resid)

    def multipliers(self, z):
        """Least-squares equilibrium multipliers and the implied bound multipliers at ``z`` (warm start):
        ``grad f + Jg^T lam_g + lam_x = 0`` with ``lam_x`` nonzero only at active activation bounds (CasADi's
        sign convention: negative at a lower bound, positive at an upper bound)."""
        prob = self.prob
        _, _, grad, Jg = prob.evaluate(z)[:4]
        a = z[prob.n:]
        tol = BOUND_TOL
        free = np.r_[np.ones(prob.n, bool), (a > tol) & (a < 1 - tol)]
        lam = np.linalg.lstsq(Jg[:, free].T, -grad[free], rcond=None)[0]
        r = grad + Jg.T @ lam
        lo = np.r_[np.zeros(prob.n, bool), a <= tol]
        hi = np.r_[np.zeros(prob.n, bool), a >= 1 - tol]
        lam_x = np.zeros_like(r)
        lam_x[lo] = np.minimum(-r[lo], 0.0)
        lam_x[hi] = np.maximum(-r[hi], 0.0)
        return lam, lam_x
