"""Quasi-static multibody spine model: rigid vertebrae connected by force elements.

State of a batch of ``B`` scenarios with ``nb`` free bodies:
  ``x`` (B, nb, 3) positions of the bodies' reference points [m],
  ``R`` (B, nb, 3, 3) rotations from the reference configuration.
A point with reference-frame coordinates ``s`` on body ``k`` is at ``x_k + R_k (s - c_k)``.
Fixed bodies ("ground", index -1) stay at the reference.

Generalised force of a body = (force [N], moment about its reference point [N*m]) in the
reference frame. ``evaluate`` returns the sum over elements plus external loads (the
equilibrium residual) and its exact derivative with respect to a spatial increment
``(dx, dtheta)`` of every free body (``x += dx``, ``R <- exp(dtheta) R``).

Element families, each vectorised over elements and scenarios:
  * ``fibres``: two-point tension elements (ligament fibres with the softplus or Rupp law,
    constant-force cables), optional constant extra path length (via points inside a body);
  * ``contacts``: facet contact points on the upper body against a cubic surface on the lower;
  * ``discs``: 6-DOF springs (translational law in the disc frame, Eq. 3 per project axis).
Per-scenario element masks (0/1 or any weight) switch elements on and off inside one batch,
so e.g. all eight reduction stages are solved together.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import so3
from .elements.disc import disc_axial_force, disc_torque
from .elements.facet import FacetSurface, contact_penalty
from .elements.ligament import rupp_force, softplus_force

LAW_SOFTPLUS, LAW_RUPP, LAW_CABLE = 0, 1, 2
GROUND = -1


@dataclass
class DiscSpec:
    upper: int
    lower: int
    centre: np.ndarray          # (3,) reference frame [m]
    frame: np.ndarray           # (3, 3) rows e1, e2, e3 (= disc normal), fixed in the lower body
    k_quadratic: float          # N/m^2
    k_linear: float             # N/m
    k_shear: float              # N/m
    k_tension: float            # N/m
    torque: dict                # direction -> (p1, p2, p3)
    name: str = ""


@dataclass
class SpineModel:
    """A set of bodies and force elements. Build with the ``add_*`` methods, then ``finalize``."""

    body_names: list = field(default_factory=list)
    centroids: list = field(default_factory=list)
    fixed_names: list = field(default_factory=list)
    fixed_centroids: list = field(default_factory=list)
    _fibres: list = field(default_factory=list)
    _contacts: list = field(default_factory=list)
    surfaces: list = field(default_factory=list)
    discs: list = field(default_factory=list)
    fibre_groups: list = field(default_factory=list)   # (name, kind, level) per group id
    contact_eps: float = 5e-5                          # contact smoothing width [m]
    slack_width_pct: float = 0.5                       # ligament slack ramp [% strain]

    # ---------------------------------------------------------------- building
    def add_body(self, name, centroid, fixed=False):
        if fixed:
            self.fixed_names.append(name)
            self.fixed_centroids.append(np.asarray(centroid, float))
            return GROUND
        self.body_names.append(name)
        self.centroids.append(np.asarray(centroid, float))
        return len(self.body_names) - 1

    def body_index(self, name):
        if name in self.body_names:
            return self.body_names.index(name)
        if name in self.fixed_names:
            return GROUND
        raise KeyError(f"unknown body {name!r}; bodies: {self.body_names + self.fixed_names}")

    def add_fibre_group(self, name, kind, level, upper, lower, s_upper, s_lower, extra_length,
                        law, params, prestrain_pct=0.0, scale=None):
        """Add the fibres of one ligament (or one cable) as a group.

        ``law``: 'softplus' (params a, b, c, d [N, %]), 'rupp' (params l_a, dF0, nu, K_nl, K_l
        from ``elements.ligament.rupp_shape``; per-strand force times ``scale``) or 'cable'
        (params (tension [N],)). Slack length of each fibre = reference length / (1 + prestrain).
        ``scale`` multiplies each fibre's law force; default 1/n_fibres (a ligament's force is
        shared by its fibres).
        """
        s_upper = np.atleast_2d(np.asarray(s_upper, float))
        s_lower = np.atleast_2d(np.asarray(s_lower, float))
        n = s_upper.shape[0]
        extra = np.broadcast_to(np.asarray(extra_length, float), (n,))
        l_ref = np.linalg.norm(s_upper - s_lower, axis=1) + extra
        if np.any(l_ref <= 0):
            raise ValueError(f"fibre group {name!r} at {level}: zero reference length")
        l0 = l_ref / (1.0 + prestrain_pct / 100.0)
        gid = len(self.fibre_groups)
        self.fibre_groups.append((name, kind, level))
        code = {"softplus": LAW_SOFTPLUS, "rupp": LAW_RUPP, "cable": LAW_CABLE}[law]
        p = np.zeros(5)
        p[: len(params)] = params
        if scale is None:
            scale = 1.0 / n if law != "cable" else 1.0
        for i in range(n):
            self._fibres.append((upper, lower, s_upper[i], s_lower[i], extra[i], l0[i], code, p, scale, gid))
        return gid

    def add_facet(self, upper, lower, surface: FacetSurface, points, stiffness):
        """Contact points (n, 3) on ``upper`` against ``surface`` fixed to ``lower``; joint stiffness [N/m]."""
        sid = len(self.surfaces)
        self.surfaces.append(surface)
        pts = np.atleast_2d(np.asarray(points, float))
        for q in pts:
            self._contacts.append((upper, lower, q, sid, stiffness / len(pts)))
        return sid

    def add_disc(self, spec: DiscSpec):
        self.discs.append(spec)

    def finalize(self):
        c = np.array(self.centroids, float).reshape(-1, 3)
        self.c = c
        self.nb = len(self.body_names)
        f = self._fibres
        self.nf = len(f)
        self.f_a = np.array([e[0] for e in f], int)
        self.f_b = np.array([e[1] for e in f], int)
        self.f_sa = np.array([e[2] for e in f], float).reshape(-1, 3)
        self.f_sb = np.array([e[3] for e in f], float).reshape(-1, 3)
        self.f_extra = np.array([e[4] for e in f], float)
        self.f_l0 = np.array([e[5] for e in f], float)
        self.f_law = np.array([e[6] for e in f], int)
        self.f_par = np.array([e[7] for e in f], float).reshape(-1, 5)
        self.f_scale = np.array([e[8] for e in f], float)
        self.f_group = np.array([e[9] for e in f], int)
        k = self._contacts
        self.nc = len(k)
        self.k_a = np.array([e[0] for e in k], int)
        self.k_b = np.array([e[1] for e in k], int)
        self.k_s = np.array([e[2] for e in k], float).reshape(-1, 3)
        self.k_surf = np.array([e[3] for e in k], int)
        self.k_stiff = np.array([e[4] for e in k], float)
        self.nd = len(self.discs)
        return self

    # ---------------------------------------------------------------- state
    def reference_state(self, batch=1):
        x = np.broadcast_to(self.c, (batch, self.nb, 3)).copy()
        R = np.broadcast_to(np.eye(3), (batch, self.nb, 3, 3)).copy()
        return x, R

    def _pose(self, x, R, idx):
        """Positions/rotations/centroids of bodies ``idx`` (ground -> identity at reference)."""
        B = x.shape[0]
        free = idx >= 0
        ii = np.where(free, idx, 0)
        xb = np.where(free[None, :, None], x[:, ii], 0.0)
        Rb = np.where(free[None, :, None, None], R[:, ii], np.eye(3))
        cb = np.where(free[:, None], self.c[ii] if self.nb else 0.0, 0.0)
        return xb, Rb, np.broadcast_to(cb, (B,) + cb.shape)

    def _points(self, x, R, idx, s):
        xb, Rb, cb = self._pose(x, R, idx)
        p = xb + np.einsum("bnij,bnj->bni", Rb, s[None] - cb)
        return p, xb, Rb

    # ---------------------------------------------------------------- assembly helpers
    def _scatter(self, Q, J, ia, ib, QA, QB, AA, AB, BA, BB):
        """Add per-element generalized forces and 6x6 blocks to the global arrays."""
        nb = self.nb
        onehot = np.zeros((nb + 1, len(ia)))
        onehot[np.where(ia >= 0, ia, nb), np.arange(len(ia))] = 1.0
        SA = onehot[:nb]
        onehot = np.zeros((nb + 1, len(ib)))
        onehot[np.where(ib >= 0, ib, nb), np.arange(len(ib))] = 1.0
        SB = onehot[:nb]
        Q += np.einsum("mn,bnk->bmk", SA, QA) + np.einsum("mn,bnk->bmk", SB, QB)
        if J is not None:
            for S1, S2, blk in ((SA, SA, AA), (SA, SB, AB), (SB, SA, BA), (SB, SB, BB)):
                J += np.einsum("mn,pn,bnkl->bmkpl", S1, S2, blk)

    @staticmethod
    def _GtKG(K, ra, rb):
        """G_a^T K G_b with G = [I, -[r]x] -> (..., 6, 6)."""
        Ha, Hb = so3.hat(ra), so3.hat(rb)
        out = np.empty(K.shape[:-2] + (6, 6))
        out[..., :3, :3] = K
        out[..., :3, 3:] = -K @ Hb
        out[..., 3:, :3] = Ha @ K
        out[..., 3:, 3:] = -Ha @ K @ Hb
        return out

    # ---------------------------------------------------------------- evaluation
    def fibre_state(self, x, R, fmask=1.0):
        """Fibre lengths [m], strains [%] and tensions [N] (B, nf)."""
        pa, _, _ = self._points(x, R, self.f_a, self.f_sa)
        pb, _, _ = self._points(x, R, self.f_b, self.f_sb)
        d = pa - pb
        dn = np.linalg.norm(d, axis=-1)
        length = dn + self.f_extra
        T, dT = self._tension(length)
        return length, (length / self.f_l0 - 1.0) * 100.0, T * fmask, dT * fmask, d, dn, pa, pb

    def _tension(self, length):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return self._tension_raw(length)

    def _tension_raw(self, length):
        par = self.f_par
        eps = (length / self.f_l0 - 1.0) * 100.0
        Ts, dTs = softplus_force(eps, par[:, 0], par[:, 1], par[:, 2], par[:, 3], self.slack_width_pct)
        dTs = dTs * 100.0 / self.f_l0
        Tr, dTr = rupp_force(length - self.f_l0, par[:, 0], par[:, 1], par[:, 2], par[:, 3], par[:, 4])
        law = self.f_law
        T = np.where(law == LAW_SOFTPLUS, Ts, np.where(law == LAW_RUPP, Tr, par[:, 0]))
        dT = np.where(law == LAW_SOFTPLUS, dTs, np.where(law == LAW_RUPP, dTr, 0.0))
        return T * self.f_scale, dT * self.f_scale

    def evaluate(self, x, R, loads=None, fmask=1.0, cmask=1.0, jacobian=True, params=None):
        """Residual Q (B, nb, 6) and Jacobian dQ/d(dx, dtheta) (B, nb, 6, nb, 6).

        ``loads`` (B, nb, 6): external force and moment (about the reference point) per body.
        ``fmask`` (B, nf) / ``cmask`` (B, nc): element weights per scenario (broadcastable).
        ``params``: optional dict of per-scenario overrides, e.g. {'k_tension': (B,)}.
        """
        B, nb = x.shape[0], self.nb
        Q = np.zeros((B, nb, 6)) if loads is None else np.array(loads, float, copy=True)
        J = np.zeros((B, nb, 6, nb, 6)) if jacobian else None
        if self.nf:
            self._add_fibres(x, R, Q, J, fmask)
        if self.nc:
            self._add_contacts(x, R, Q, J, cmask)
        if self.nd:
            self._add_discs(x, R, Q, J, params or {})
        return Q, J

    def _two_point(self, Q, J, ia, ib, f, K, pa, pb, xa, xb):
        ra, rb = pa - xa, pb - xb
        Ha, Hb = so3.hat(ra), so3.hat(rb)
        QA = np.concatenate([f, np.cross(ra, f)], axis=-1)
        QB = np.concatenate([-f, -np.cross(rb, f)], axis=-1)
        if J is None:
            self._scatter(Q, None, ia, ib, QA, QB, None, None, None, None)
            return
        F = so3.hat(f)
        AA = self._GtKG(K, ra, ra)
        AA[..., 3:, 3:] += F @ Ha
        BB = self._GtKG(K, rb, rb)
        BB[..., 3:, 3:] += -F @ Hb
        AB = -self._GtKG(K, ra, rb)
        BA = -self._GtKG(K, rb, ra)
        self._scatter(Q, J, ia, ib, QA, QB, AA, AB, BA, BB)

    def _add_fibres(self, x, R, Q, J, fmask):
        _, _, T, dT, d, dn, pa, pb = self.fibre_state(x, R, fmask)
        xa = self._pose(x, R, self.f_a)[0]
        xb = self._pose(x, R, self.f_b)[0]
        u = d / dn[..., None]
        f = -T[..., None] * u                     # force on the upper end (pulls towards lower)
        uu = u[..., :, None] * u[..., None, :]
        K = -(dT[..., None, None] * uu + (T / dn)[..., None, None] * (np.eye(3) - uu))
        self._two_point(Q, J, self.f_a, self.f_b, f, K, pa, pb, xa, xb)

    def _body_relative(self, Q, J, ia, ib, f, K, p, xa, xb):
        """Point force f at p (on body ia) from a law fixed in body ib; K = df/dp (world)."""
        ra, rB = p - xa, p - xb
        Ha, HB, F = so3.hat(ra), so3.hat(rB), so3.hat(f)
        QA = np.concatenate([f, np.cross(ra, f)], axis=-1)
        QB = np.concatenate([-f, -np.cross(rB, f)], axis=-1)
        if J is None:
            self._scatter(Q, None, ia, ib, QA, QB, None, None, None, None)
            return
        AA = self._GtKG(K, ra, ra)
        AA[..., 3:, 3:] += F @ Ha
        AB = -self._GtKG(K, ra, rB)
        AB[..., :3, 3:] += -F
        AB[..., 3:, 3:] += -Ha @ F
        BA = -self._GtKG(K, rB, ra)
        BA[..., 3:, :3] += F
        BA[..., 3:, 3:] += -F @ Ha
        BB = self._GtKG(K, rB, rB)
        BB[..., :3, 3:] += F
        BB[..., 3:, :3] += -F
        BB[..., 3:, 3:] += HB @ F
        self._scatter(Q, J, ia, ib, QA, QB, AA, AB, BA, BB)

    def _add_contacts(self, x, R, Q, J, cmask):
        p, xa, _ = self._points(x, R, self.k_a, self.k_s)
        xB, RB, cB = self._pose(x, R, self.k_b)
        P = np.einsum("bnji,bnj->bni", RB, p - xB) + cB         # reference coords in the lower body
        g = np.empty(P.shape[:-1])
        grad = np.empty(P.shape)
        hess = np.empty(P.shape + (3,))
        for sid, surf in enumerate(self.surfaces):
            sel = self.k_surf == sid
            g[:, sel], grad[:, sel], hess[:, sel] = surf.gap(P[:, sel])
        Fm, dFm = contact_penalty(-g, self.k_stiff, self.contact_eps)
        Fm, dFm = Fm * cmask, dFm * cmask
        f_loc = Fm[..., None] * grad
        K_loc = -dFm[..., None, None] * grad[..., :, None] * grad[..., None, :] + Fm[..., None, None] * hess
        f = np.einsum("bnij,bnj->bni", RB, f_loc)
        K = RB @ K_loc @ np.swapaxes(RB, -1, -2)
        self._body_relative(Q, J, self.k_a, self.k_b, f, K, p, xa, xB)

    def _add_discs(self, x, R, Q, J, params):
        for spec in self.discs:
            ia, ib = np.array([spec.upper]), np.array([spec.lower])
            p, xa, Ra = self._points(x, R, ia, spec.centre[None])
            xB, RB, cB = self._pose(x, R, ib)
            # translation: law in the disc frame fixed to the lower body
            P = np.einsum("bnji,bnj->bni", RB, p - xB) + cB
            r = (P - spec.centre) @ spec.frame.T
            kt = params.get("k_tension", spec.k_tension)
            kt = np.reshape(kt, (-1, 1)) if np.ndim(kt) else kt
            Fz, dFz = disc_axial_force(r[..., 2], spec.k_quadratic, spec.k_linear, kt)
            F_loc = np.stack([-spec.k_shear * r[..., 0], -spec.k_shear * r[..., 1], Fz], axis=-1)
            D = np.zeros(r.shape + (3,))
            D[..., 0, 0] = -spec.k_shear
            D[..., 1, 1] = -spec.k_shear
            D[..., 2, 2] = dFz
            f_B = F_loc @ spec.frame                                  # in lower-body coordinates
            K_B = spec.frame.T @ D @ spec.frame
            f = np.einsum("bnij,bnj->bni", RB, f_B)
            K = RB @ K_B @ np.swapaxes(RB, -1, -2)
            self._body_relative(Q, J, ia, ib, f, K, p, xa, xB)
            # rotation: Eq. 3 per project axis of the lower body
            Rrel = np.swapaxes(RB[:, 0], -1, -2) @ Ra[:, 0]
            phi = so3.log(Rrel)
            T, dT = disc_torque(phi, spec.torque)
            tau = np.einsum("bij,bj->bi", RB[:, 0], T)                 # torque on the lower body
            if spec.upper >= 0:
                Q[:, spec.upper, 3:] -= tau
            if spec.lower >= 0:
                Q[:, spec.lower, 3:] += tau
            if J is None:
                continue
            Jinv = so3.left_jacobian_inverse(phi)
            M = RB[:, 0] @ (dT[..., :, None] * Jinv) @ np.swapaxes(RB[:, 0], -1, -2)
            Ht = so3.hat(tau)
            a, b = spec.upper, spec.lower
            if a >= 0:
                J[:, a, 3:, a, 3:] -= M
            if a >= 0 and b >= 0:
                J[:, a, 3:, b, 3:] += M + Ht
                J[:, b, 3:, a, 3:] += M
            if b >= 0:
                J[:, b, 3:, b, 3:] += -M - Ht

    # ---------------------------------------------------------------- reporting
    def disc_loads(self, x, R):
        """Per disc: relative rotation vector [rad] (B, nd, 3), disc-frame displacement [m]
        (B, nd, 3), disc-frame force on the upper body [N] (B, nd, 3) and torque [N*m] (B, nd, 3)."""
        out = {"phi": [], "r": [], "force": [], "torque": []}
        for spec in self.discs:
            ia, ib = np.array([spec.upper]), np.array([spec.lower])
            p, _, Ra = self._points(x, R, ia, spec.centre[None])
            xB, RB, cB = self._pose(x, R, ib)
            P = np.einsum("bnji,bnj->bni", RB, p - xB) + cB
            r = ((P - spec.centre) @ spec.frame.T)[:, 0]
            Fz, _ = disc_axial_force(r[:, 2], spec.k_quadratic, spec.k_linear, spec.k_tension)
            F = np.stack([-spec.k_shear * r[:, 0], -spec.k_shear * r[:, 1], Fz], axis=-1)
            phi = so3.log(np.swapaxes(RB[:, 0], -1, -2) @ Ra[:, 0])
            T, _ = disc_torque(phi, spec.torque)
            out["phi"].append(phi)
            out["r"].append(r)
            out["force"].append(F)
            out["torque"].append(-T)
        return {k: np.stack(v, axis=1) for k, v in out.items()}

    def contact_forces(self, x, R, cmask=1.0):
        """Total normal contact force [N] per facet surface (B, n_surfaces)."""
        p, _, _ = self._points(x, R, self.k_a, self.k_s)
        xB, RB, cB = self._pose(x, R, self.k_b)
        P = np.einsum("bnji,bnj->bni", RB, p - xB) + cB
        out = np.zeros((x.shape[0], len(self.surfaces)))
        for sid, surf in enumerate(self.surfaces):
            sel = self.k_surf == sid
            g, grad, _ = surf.gap(P[:, sel])
            Fm, _ = contact_penalty(-g, self.k_stiff[sel], self.contact_eps)
            Fm = Fm * (cmask[..., sel] if np.ndim(cmask) else cmask)
            out[:, sid] = (Fm * np.linalg.norm(grad, axis=-1)).sum(-1)
        return out

    def group_forces(self, x, R, fmask=1.0):
        """Total tension [N] per fibre group (B, n_groups)."""
        T = self.fibre_state(x, R, fmask)[2]
        G = np.zeros((len(self.fibre_groups), self.nf))
        G[self.f_group, np.arange(self.nf)] = 1.0
        return T @ G.T
