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
from .elements.ligament import LAW_CABLE, LAW_RUPP, LAW_SOFTPLUS, rupp_force, slack_length, softplus_force

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
    law: str = "eq3"            # torque law (lumbar.mechanics.elements.disc.TORQUE_LAWS); "eq3" on the compiled core
    k_shear_lateral: float | None = None   # N/m, lateral shear where it differs from k_shear (anterior-posterior)


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
                        law, params, prestrain=0.0, scale=None):
        """Add the fibres of one ligament (or one cable) as a group.

        ``law``: 'softplus' (params a, b, c, d [N, %]), 'rupp' (params l_a, dF0, nu, K_nl, K_l
        from ``elements.ligament.rupp_shape``; per-strand force times ``scale``) or 'cable'
        (params (tension [N],)). Slack length of each fibre = reference length / (1 + prestrain), ``prestrain`` a
        strain (fraction, e.g. ``law.prestrain`` of a characteristic set's law).
        ``scale`` multiplies each fibre's law force; default 1/n_fibres (a ligament's force is
        shared by its fibres). ``prestrain`` and ``params`` may also be given per fibre ((n,) and (n, k)), e.g.
        a law defined on elongation, whose parameters in each fibre's own strain depend on its slack length
        (:func:`lumbar.experiments.fsu.softplus_fibre_params`).
        """
        s_upper = np.atleast_2d(np.asarray(s_upper, float))
        s_lower = np.atleast_2d(np.asarray(s_lower, float))
        n = s_upper.shape[0]
        extra = np.broadcast_to(np.asarray(extra_length, float), (n,))
        l_ref = np.linalg.norm(s_upper - s_lower, axis=1) + extra
        if np.any(l_ref <= 0):
            raise ValueError(f"fibre group {name!r} at {level}: zero reference length")
        l0 = np.broadcast_to(slack_length(l_ref, np.asarray(prestrain, float)), (n,))
        if np.any(~np.isfinite(l0) | (l0 <= 0)):
            raise ValueError(f"fibre group {name!r} at {level}: slack length <= 0 (prestrain {prestrain!r})")
        gid = len(self.fibre_groups)
        self.fibre_groups.append((name, kind, level))
        code = {"softplus": LAW_SOFTPLUS, "rupp": LAW_RUPP, "cable": LAW_CABLE}[law]
        par = np.asarray(params, float)
        P = np.zeros((n, 5))
        if par.ndim == 2:
            P[:, : par.shape[1]] = par
        else:
            P[:, : par.size] = par
        if scale is None:
            scale = 1.0 / n if law != "cable" else 1.0
        for i in range(n):
            self._fibres.append((upper, lower, s_upper[i], s_lower[i], extra[i], l0[i], code, P[i], scale, gid))
        return gid

    def add_facet(self, upper, lower, surface: FacetSurface, points, facet_stiffness_n_per_m):
        """Contact points (n, 3) on ``upper`` against ``surface`` fixed to ``lower``; the joint's stiffness [N/m] is
        shared equally by its n points (``k_stiff``, the kernel's per-point array, is joint stiffness / n: a joint
        pressed evenly carries the same force whatever its number of points)."""
        sid = len(self.surfaces)
        self.surfaces.append(surface)
        pts = np.atleast_2d(np.asarray(points, float))
        for q in pts:
            self._contacts.append((upper, lower, q, sid, facet_stiffness_n_per_m / len(pts), 1.0 / len(pts)))
        return sid

    def set_facet_stiffness(self, facet_stiffness_n_per_m, surfaces=None):
        """Set, in place on a finalized model, the stiffness [N/m] of every facet joint (or of the contact surfaces
        ``surfaces``, ids from :meth:`add_facet`): the one way to change it after the build (each point gets its
        share, as :meth:`add_facet` gives it). A value may be given per selected point (an array)."""
        k = np.asarray(facet_stiffness_n_per_m, float)
        if not np.all(np.isfinite(k)) or np.any(k < 0):
            raise ValueError(f"facet_stiffness_n_per_m must be finite and >= 0 N/m, got {facet_stiffness_n_per_m}")
        sel = slice(None) if surfaces is None else np.isin(self.k_surf, list(surfaces))
        self.k_stiff[sel] = k * self.k_share[sel]

    def facet_stiffness(self) -> np.ndarray:
        """The stiffness [N/m] of each contact surface's joint (summed over its points), in surface order."""
        return np.bincount(self.k_surf, weights=self.k_stiff, minlength=len(self.surfaces))

    def kernel_supported(self) -> bool:
        """Whether the compiled core computes this model: every element it has (fibres, facet contact, discs with
        the Eq. 3 or the ``cubic_deg`` torque law and one or two shear stiffnesses, paper 2's 6-DOF springs among
        them)."""
        from .elements.disc import TORQUE_LAWS  # noqa: PLC0415
        return all(d.law in TORQUE_LAWS for d in self.discs)

    def add_disc(self, spec: DiscSpec):
        from .elements.disc import TORQUE_LAWS  # noqa: PLC0415
        if spec.law not in TORQUE_LAWS:
            raise ValueError(f"disc {spec.name!r}: unknown torque law {spec.law!r}; expected one of {TORQUE_LAWS}")
        spec._ia, spec._ib = np.array([spec.upper]), np.array([spec.lower])
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
        # reference (as-built) length of every fibre [m]: what a law defined on elongation needs
        self.f_lref = np.linalg.norm(self.f_sa - self.f_sb, axis=1) + self.f_extra if self.nf else np.zeros(0)
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
        self.k_stiff = np.array([e[4] for e in k], float)       # per point: joint stiffness x k_share [N/m]
        self.k_share = np.array([e[5] for e in k], float)       # each point's share of its joint (1 / n points)
        self.nd = len(self.discs)
        return self

    # ---------------------------------------------------------------- state
    def reference_state(self, batch=1):
        x = np.broadcast_to(self.c, (batch, self.nb, 3)).copy()
        R = np.broadcast_to(np.eye(3), (batch, self.nb, 3, 3)).copy()
        return x, R

    def _groups(self, idx):
        """{body: element indices} for an element-to-body index array (cached per array)."""
        key = id(idx)
        cache = self.__dict__.setdefault("_group_cache", {})
        if key not in cache:
            g = {}
            for n, b in enumerate(np.asarray(idx).tolist()):
                g.setdefault(b, []).append(n)
            cache[key] = (idx, [(b, np.array(v)) for b, v in g.items()])
        return cache[key][1]

    def _pairs(self, ia, ib):
        """[((body a, body b), element indices)] for two element-to-body index arrays (cached per pair of
        arrays). Index arrays, not slices: a sum over a strided view may round differently from the same sum
        over a copy, and the results are kept byte-identical."""
        key = (id(ia), id(ib))
        cache = self.__dict__.setdefault("_pair_cache", {})
        if key not in cache:
            pairs = {}
            for n, k in enumerate(zip(np.asarray(ia).tolist(), np.asarray(ib).tolist())):
                pairs.setdefault(k, []).append(n)
            cache[key] = (ia, ib, [(k, np.array(v)) for k, v in pairs.items()])
        return cache[key][2]

    def _attach(self, x, R, idx, s):
        """World positions p (B, n, 3) of reference points s (n, 3) on bodies idx, and x of each body."""
        B = x.shape[0]
        p = np.empty((B, len(idx), 3))
        xe = np.zeros((B, len(idx), 3))
        for b, sel in self._groups(idx):
            if b < 0:
                p[:, sel] = s[sel]
            else:
                p[:, sel] = x[:, b, None, :] + (s[sel] - self.c[b]) @ np.swapaxes(R[:, b], -1, -2)
                xe[:, sel] = x[:, b, None, :]
        return p, xe

    def _to_body(self, x, R, idx, p):
        """Reference-frame coordinates, in bodies idx, of world points p (B, n, 3)."""
        P = np.empty_like(p)
        for b, sel in self._groups(idx):
            P[:, sel] = p[:, sel] if b < 0 else (p[:, sel] - x[:, b, None, :]) @ R[:, b] + self.c[b]
        return P

    def _rotate(self, R, idx, v):
        """Rotate body-fixed vectors v (B, n, ..., 3) of bodies idx into the world frame."""
        out = np.empty_like(v)
        for b, sel in self._groups(idx):
            if b < 0:
                out[:, sel] = v[:, sel]
            else:
                Rt = np.swapaxes(R[:, b], -1, -2)
                Rt = Rt.reshape(Rt.shape[:1] + (1,) * (v.ndim - 3) + (3, 3))
                out[:, sel] = v[:, sel] @ Rt
        return out

    # ---------------------------------------------------------------- assembly
    # Every element stiffness K = df/d(relative displacement) used here is a sum of weighted
    # rank-1 terms w v v^T. With G = [I, -[r]x], G_a^T (w v v^T) G_b = w [v; ra x v][v; rb x v]^T,
    # so each 6x6 block summed over elements is one batched GEMM. Geometric (rotation) terms use
    # [a]x[b]x = b a^T - (a.b) I.
    @staticmethod
    def _outer_sum(a, b):
        """sum_n a_n b_n^T for (B, n, 3) arrays -> (B, 3, 3)."""
        return np.swapaxes(a, -1, -2) @ b

    @staticmethod
    def _hatprod_sum(a, b):
        """sum_n [a_n]x [b_n]x = sum_n (b_n a_n^T - (a_n . b_n) I) -> (B, 3, 3)."""
        out = np.swapaxes(b, -1, -2) @ a
        tr = np.einsum("bni,bni->b", a, b)
        out[:, 0, 0] -= tr
        out[:, 1, 1] -= tr
        out[:, 2, 2] -= tr
        return out

    def _assemble(self, Q, J, ia, ib, f, ra, rb, w, v, body_relative):
        """Add generalized forces and Jacobian blocks of point elements.

        ia/ib (n,) body of the point / of the other attachment (or of the law's frame);
        f (B, n, 3) force on body ia at its point; ra, rb (B, n, 3) lever arms of the point about
        each body's reference point; w (B, n, T), v (B, n, T, 3) the rank-1 terms of
        K = df/dp (world); ``body_relative``: the law is fixed in body ib (facets, disc translation)
        instead of depending on the distance between two attached points (fibres).
        """
        Qa = np.concatenate([f, so3.cross(ra, f)], axis=-1)
        Qb = -np.concatenate([f, so3.cross(rb, f)], axis=-1)
        for (i, j), sel in self._pairs(ia, ib):
            if i >= 0:
                Q[:, i] += Qa[:, sel].sum(1)
            if j >= 0:
                Q[:, j] += Qb[:, sel].sum(1)
            if J is None:
                continue
            B = w.shape[0]
            vs = v[:, sel]
            fa = f[:, sel]
            wf = w[:, sel].reshape(B, -1, 1)
            ga = np.concatenate([vs, so3.cross(ra[:, sel, None, :], vs)], axis=-1).reshape(B, -1, 6)
            gb = np.concatenate([vs, so3.cross(rb[:, sel, None, :], vs)], axis=-1).reshape(B, -1, 6)
            ra_s, rb_s = ra[:, sel], rb[:, sel]
            if i >= 0:
                blk = np.swapaxes(ga * wf, -1, -2) @ ga
                blk[:, 3:, 3:] += self._hatprod_sum(fa, ra_s)
                J[:, i, :, i, :] += blk
            if j >= 0:
                blk = np.swapaxes(gb * wf, -1, -2) @ gb
                if body_relative:
                    Fs = so3.hat(fa.sum(1))
                    blk[:, :3, 3:] += Fs
                    blk[:, 3:, :3] -= Fs
                    blk[:, 3:, 3:] += self._hatprod_sum(rb_s, fa)
                else:
                    blk[:, 3:, 3:] -= self._hatprod_sum(fa, rb_s)
                J[:, j, :, j, :] += blk
            if i >= 0 and j >= 0:
                ab = -(np.swapaxes(ga * wf, -1, -2) @ gb)
                ba = -(np.swapaxes(gb * wf, -1, -2) @ ga)
                if body_relative:
                    Fs = so3.hat(fa.sum(1))
                    ab[:, :3, 3:] -= Fs
                    ab[:, 3:, 3:] -= self._hatprod_sum(ra_s, fa)
                    ba[:, 3:, :3] += Fs
                    ba[:, 3:, 3:] -= self._hatprod_sum(fa, ra_s)
                J[:, i, :, j, :] += ab
                J[:, j, :, i, :] += ba

    # ---------------------------------------------------------------- evaluation
    def fibre_state(self, x, R, fmask=1.0, params=None):
        """Fibre lengths [m], strains [%] and tensions [N] (B, nf).

        ``params["fibre_l0_scale"]`` (B, nf) or (B, 1): per-scenario multiplier of the slack lengths
        (a prestrain change: scale = (1 + eps0) / (1 + eps0'))."""
        pa, _ = self._attach(x, R, self.f_a, self.f_sa)
        pb, _ = self._attach(x, R, self.f_b, self.f_sb)
        d = pa - pb
        dn = np.linalg.norm(d, axis=-1)
        length = dn + self.f_extra
        l0 = self.f_l0
        if params and params.get("fibre_l0_scale") is not None:
            l0 = l0 * np.asarray(params["fibre_l0_scale"], float).reshape(length.shape[0], -1)
        T, dT = self._tension(length, l0)
        return length, (length / l0 - 1.0) * 100.0, T * fmask, dT * fmask, d, dn, pa, pb

    def _tension(self, length, l0):
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return self._tension_raw(length, l0)

    def _tension_raw(self, length, l0):
        par = self.f_par
        eps = (length / l0 - 1.0) * 100.0
        Ts, dTs = softplus_force(eps, par[:, 0], par[:, 1], par[:, 2], par[:, 3], self.slack_width_pct)
        dTs = dTs * 100.0 / l0
        Tr, dTr = rupp_force(length - l0, par[:, 0], par[:, 1], par[:, 2], par[:, 3], par[:, 4])
        law = self.f_law
        T = np.where(law == LAW_SOFTPLUS, Ts, np.where(law == LAW_RUPP, Tr, par[:, 0]))
        dT = np.where(law == LAW_SOFTPLUS, dTs, np.where(law == LAW_RUPP, dTr, 0.0))
        return T * self.f_scale, dT * self.f_scale

    def evaluate(self, x, R, loads=None, fmask=1.0, cmask=1.0, jacobian=True, params=None):
        """Residual Q (B, nb, 6) and Jacobian dQ/d(dx, dtheta) (B, nb, 6, nb, 6) (None without ``jacobian``).

        On the compiled core (:mod:`lumbar.mechanics.kernel`) when it is active, else on the numpy reference
        :meth:`evaluate_reference` (same arguments, same results up to round-off)."""
        from . import kernel  # noqa: PLC0415 - numba only where equilibria are computed (lumbar/__init__.py)
        if kernel.active() and self.kernel_supported():
            return kernel.evaluate(self, x, R, loads, fmask, cmask, jacobian, params)
        return self.evaluate_reference(x, R, loads, fmask, cmask, jacobian, params)

    def evaluate_reference(self, x, R, loads=None, fmask=1.0, cmask=1.0, jacobian=True, params=None):
        """Residual Q (B, nb, 6) and Jacobian dQ/d(dx, dtheta) (B, nb, 6, nb, 6): the vectorised numpy reference.

        ``loads`` (B, nb, 6): external force and moment (about the reference point) per body.
        ``fmask`` (B, nf) / ``cmask`` (B, nc): element weights per scenario (broadcastable).
        ``params``: optional per-scenario model extensions (each vanishes at its default):
        ``k_tension`` (B,) disc tensile stiffness [N/m]; ``disc_phi_offset`` (B, 3) neutral-angle
        offset of every disc torque law [rad] (T = T_law(phi - offset)); ``fibre_l0_scale`` (B, nf)
        or (B, 1) slack-length multiplier of the fibres.
        """
        B, nb = x.shape[0], self.nb
        Q = np.zeros((B, nb, 6)) if loads is None else np.array(loads, float, copy=True)
        J = np.zeros((B, nb, 6, nb, 6)) if jacobian else None
        if self.nf:
            self._add_fibres(x, R, Q, J, fmask, params or {})
        if self.nc:
            self._add_contacts(x, R, Q, J, cmask)
        if self.nd:
            self._add_discs(x, R, Q, J, params or {})
        return Q, J

    def _add_fibres(self, x, R, Q, J, fmask, params):
        _, _, T, dT, d, dn, pa, pb = self.fibre_state(x, R, fmask, params)
        xa = self._attach(x, R, self.f_a, self.f_sa)[1]
        xb = self._attach(x, R, self.f_b, self.f_sb)[1]
        u = d / dn[..., None]
        f = -T[..., None] * u                     # force on the upper end (pulls towards lower)
        # K = -(dT u u^T + T/|d| (I - u u^T)) = alpha I + beta u u^T
        alpha = -T / dn
        beta = T / dn - dT
        Bn = u.shape[:2]
        v = np.empty(Bn + (4, 3))
        v[..., 0, :] = u
        v[..., 1:, :] = np.eye(3)
        w = np.stack([beta, alpha, alpha, alpha], axis=-1)
        self._assemble(Q, J, self.f_a, self.f_b, f, pa - xa, pb - xb, w, v, body_relative=False)

    def _add_contacts(self, x, R, Q, J, cmask):
        p, xa = self._attach(x, R, self.k_a, self.k_s)
        xB = self._attach(x, R, self.k_b, self.k_s)[1]
        P = self._to_body(x, R, self.k_b, p)                    # reference coords in the lower body
        g = np.empty(P.shape[:-1])
        grad = np.empty(P.shape)
        for sid, surf in enumerate(self.surfaces):
            sel = self.k_surf == sid
            g[:, sel], grad[:, sel], _ = surf.gap(P[:, sel], hessian=False)
        Fm, dFm = contact_penalty(-g, self.k_stiff, self.contact_eps)
        Fm, dFm = Fm * cmask, dFm * cmask
        # K = R_B (-dF grad grad^T + F hess) R_B^T, hess = -f_uu a_u a_u^T - f_vv a_v a_v^T
        Bn = g.shape
        v = np.empty(Bn + (3, 3))
        w = np.empty(Bn + (3,))
        v[..., 0, :] = grad
        w[..., 0] = -dFm
        for sid, surf in enumerate(self.surfaces):
            sel = self.k_surf == sid
            q = surf.local(P[:, sel])
            _, _, _, fuu, fvv = surf.surface(q[..., 0], q[..., 1])
            v[:, sel, 1, :] = surf.axes[0]
            v[:, sel, 2, :] = surf.axes[1]
            w[:, sel, 1] = -Fm[:, sel] * fuu
            w[:, sel, 2] = -Fm[:, sel] * fvv
        v = self._rotate(R, self.k_b, v)
        f = Fm[..., None] * v[..., 0, :]
        self._assemble(Q, J, self.k_a, self.k_b, f, p - xa, p - xB, w, v, body_relative=True)

    def _add_discs(self, x, R, Q, J, params):
        for spec in self.discs:
            ia, ib = spec._ia, spec._ib
            p, xa = self._attach(x, R, ia, spec.centre[None])
            xB = self._attach(x, R, ib, spec.centre[None])[1]
            Ra = R[:, spec.upper][:, None] if spec.upper >= 0 else np.broadcast_to(np.eye(3), (x.shape[0], 1, 3, 3))
            RB = R[:, spec.lower][:, None] if spec.lower >= 0 else np.broadcast_to(np.eye(3), (x.shape[0], 1, 3, 3))
            P = self._to_body(x, R, ib, p)
            r = (P - spec.centre) @ spec.frame.T
            kt = params.get("k_tension", spec.k_tension)
            kt = np.reshape(kt, (-1, 1)) if np.ndim(kt) else kt
            Fz, dFz = disc_axial_force(r[..., 2], spec.k_quadratic, spec.k_linear, kt)
            ksl = spec.k_shear if spec.k_shear_lateral is None else spec.k_shear_lateral
            F_loc = np.stack([-spec.k_shear * r[..., 0], -ksl * r[..., 1], Fz], axis=-1)
            D = np.zeros(r.shape + (3,))
            D[..., 0, 0] = -spec.k_shear
            D[..., 1, 1] = -ksl
            D[..., 2, 2] = dFz
            # K = R_B frame^T D frame R_B^T = sum_k D_kk (R_B e_k)(R_B e_k)^T
            v = self._rotate(R, ib, np.broadcast_to(spec.frame, (x.shape[0], 1, 3, 3)).copy())
            f = np.einsum("bnk,bnki->bni", F_loc, v)
            w = np.stack([D[..., 0, 0], D[..., 1, 1], D[..., 2, 2]], axis=-1)
            self._assemble(Q, J, ia, ib, f, p - xa, p - xB, w, v, body_relative=True)
            # rotation: Eq. 3 per project axis of the lower body
            Rrel = np.swapaxes(RB[:, 0], -1, -2) @ Ra[:, 0]
            phi = so3.log(Rrel)
            off = params.get("disc_phi_offset")
            T, dT = disc_torque(phi if off is None else phi - np.reshape(off, (-1, 3)), spec.torque, spec.law)
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
    def disc_displacement(self, x, R, k):
        """Disc-frame displacement [m] (B, 3) of disc ``k``'s upper centre from its reference (``disc_loads``'s
        ``r``, without the rest of its loads)."""
        spec = self.discs[k]
        p, _ = self._attach(x, R, spec._ia, spec.centre[None])
        P = self._to_body(x, R, spec._ib, p)
        return ((P - spec.centre) @ spec.frame.T)[:, 0]

    def disc_axial_force(self, r, k):
        """Axial force [N] on the upper body and its derivative (B,) of disc ``k`` at the disc-frame displacements
        ``r`` (B, 3) (:meth:`disc_displacement`)."""
        spec = self.discs[k]
        return disc_axial_force(r[:, 2], spec.k_quadratic, spec.k_linear, spec.k_tension)

    def disc_loads(self, x, R):
        """Per disc: relative rotation vector [rad] (B, nd, 3), disc-frame displacement [m]
        (B, nd, 3), disc-frame force on the upper body [N] (B, nd, 3) and torque [N*m] (B, nd, 3)."""
        out = {"phi": [], "r": [], "force": [], "torque": []}
        for k, spec in enumerate(self.discs):
            Ra = R[:, spec.upper][:, None] if spec.upper >= 0 else np.broadcast_to(np.eye(3), (x.shape[0], 1, 3, 3))
            RB = R[:, spec.lower][:, None] if spec.lower >= 0 else np.broadcast_to(np.eye(3), (x.shape[0], 1, 3, 3))
            r = self.disc_displacement(x, R, k)
            Fz, _ = self.disc_axial_force(r, k)
            ksl = spec.k_shear if spec.k_shear_lateral is None else spec.k_shear_lateral
            F = np.stack([-spec.k_shear * r[:, 0], -ksl * r[:, 1], Fz], axis=-1)
            phi = so3.log(np.swapaxes(RB[:, 0], -1, -2) @ Ra[:, 0])
            T, _ = disc_torque(phi, spec.torque, spec.law)
            out["phi"].append(phi)
            out["r"].append(r)
            out["force"].append(F)
            out["torque"].append(-T)
        return {k: np.stack(v, axis=1) for k, v in out.items()}

    def contact_forces(self, x, R, cmask=1.0, beyond_extent=False):
        """Total normal contact force [N] per facet surface (B, n_surfaces).

        ``beyond_extent``: only the force of the contact points that lie outside the surface's landmark extent
        (:meth:`lumbar.mechanics.elements.facet.FacetSurface.beyond_extent`), where Eq. 4 is extrapolated: the part of
        the contact force that the fitted articular surface does not cover."""
        p, _ = self._attach(x, R, self.k_a, self.k_s)
        P = self._to_body(x, R, self.k_b, p)
        out = np.zeros((x.shape[0], len(self.surfaces)))
        for sid, surf in enumerate(self.surfaces):
            sel = self.k_surf == sid
            g, grad, _ = surf.gap(P[:, sel], hessian=False)
            Fm, _ = contact_penalty(-g, self.k_stiff[sel], self.contact_eps)
            Fm = Fm * (cmask[..., sel] if np.ndim(cmask) else cmask)
            if beyond_extent:
                Fm = Fm * surf.beyond_extent(P[:, sel])
            out[:, sid] = (Fm * np.linalg.norm(grad, axis=-1)).sum(-1)
        return out

    def group_forces(self, x, R, fmask=1.0, params=None):
        """Total tension [N] per fibre group (B, n_groups)."""
        T = self.fibre_state(x, R, fmask, params)[2]
        G = np.zeros((len(self.fibre_groups), self.nf))
        G[self.f_group, np.arange(self.nf)] = 1.0
        return T @ G.T
