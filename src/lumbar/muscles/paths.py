"""Muscle paths through their sites: lengths, length gradients (moment arms) and Hill-type tension.

A path is a polyline through its sites (via points included); segments between two sites on the same body
(or on two fixed bodies) have constant length. Generalised quantities use the project's spatial increment
``(dx, dtheta)`` per free body (docs/design.md): ``dL/dq`` is the (B, nm, nb, 6) gradient, and the
generalised force of a muscle with tension T is ``-T dL/dq`` (its "moment arms" are ``-dL/dtheta``).

Tension (paper 2, Sect. 2.1, rigid tendon)::

    F = PCSA * (a * SpT * f_active(SL / 2.8 um) + K * f_passive(SL / SSL)) * cos(pennation)

Sarcomere length (our reading of Supplementary S1, which is not available here): the fibre takes the
fraction ``fibre_ratio`` of the musculotendon length in the reference (supine/prone, as-segmented) posture,
where its sarcomeres have the group's in-situ length; the tendon is rigid, so
``SL = SL_in_situ * (L - (1 - r) L_ref) / (r L_ref)``; the optimal fibre length this implies is
``L_opt = r L_ref * 2.8 / SL_in_situ`` (Christophy et al. 2012 normalisation).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..mechanics import kernel
from . import compiled
from .millard import ACTIVE_FL, PASSIVE_FL
from .muscle_set import OPTIMAL_SL_UM, MuscleSet

N_PER_CM2 = 1.0e4   # N/cm^2 -> Pa


@dataclass
class MuscleProperties:
    """Per-fascicle parameters (arrays of length nm); SI except sarcomere lengths in um."""

    pcsa_m2: np.ndarray
    spt_pa: np.ndarray
    k_pa: np.ndarray
    ssl_um: np.ndarray
    in_situ_sl_um: np.ndarray
    pennation_rad: np.ndarray
    fibre_ratio: np.ndarray
    l_ref_m: np.ndarray

    def __post_init__(self):
        for f in ("pcsa_m2", "spt_pa", "ssl_um", "in_situ_sl_um", "fibre_ratio", "l_ref_m"):
            v = np.asarray(getattr(self, f), float)
            if np.any(~np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"muscle property {f} must be finite and > 0 for every fascicle")
        k = np.asarray(self.k_pa, float)
        if np.any(~np.isfinite(k)) or np.any(k < 0):
            raise ValueError("muscle property k_pa (passive scaling K) must be finite and >= 0")
        p = np.asarray(self.pennation_rad, float)
        if np.any(p < 0) or np.any(p >= np.pi / 2):
            raise ValueError("muscle property pennation_rad must be in [0, pi/2)")

    def with_(self, **kw) -> "MuscleProperties":
        return replace(self, **kw)

    @property
    def l_opt_m(self):
        return self.fibre_ratio * self.l_ref_m * OPTIMAL_SL_UM / self.in_situ_sl_um

    def sarcomere_length(self, L):
        r, Lr = self.fibre_ratio, self.l_ref_m
        return self.in_situ_sl_um * (L - (1.0 - r) * Lr) / (r * Lr)

    def tension(self, L, a):
        """Tension T, dT/dL, active part at a=1 (F_iso(L)) and passive part, all (B, nm)."""
        sl = self.sarcomere_length(L)
        dsl = self.in_situ_sl_um / (self.fibre_ratio * self.l_ref_m)
        fa, dfa = ACTIVE_FL.value_and_slope(sl / OPTIMAL_SL_UM)
        fp, dfp = PASSIVE_FL.value_and_slope(sl / self.ssl_um)
        c = self.pcsa_m2 * np.cos(self.pennation_rad)
        act1 = c * self.spt_pa * fa
        pas = c * self.k_pa * fp
        T = a * act1 + pas
        dT = c * (a * self.spt_pa * dfa / OPTIMAL_SL_UM + self.k_pa * dfp / self.ssl_um) * dsl
        return T, dT, act1, pas


def baseline_properties(ms: MuscleSet, l_ref_m, ssl_um=2.8, k_n_per_cm2=100.0, spt_n_per_cm2=100.0):
    if ssl_um <= 0:
        raise ValueError(f"slack sarcomere length (ssl_um) must be > 0 um, got {ssl_um}")
    n = ms.n
    return MuscleProperties(pcsa_m2=ms.pcsa_m2.copy(), spt_pa=np.full(n, spt_n_per_cm2 * N_PER_CM2),
                            k_pa=np.full(n, k_n_per_cm2 * N_PER_CM2), ssl_um=np.full(n, float(ssl_um)),
                            in_situ_sl_um=ms.in_situ_sl_um.copy(), pennation_rad=ms.pennation_rad.copy(),
                            fibre_ratio=ms.fibre_ratio.copy(), l_ref_m=np.asarray(l_ref_m, float).copy())


class MusclePaths:
    """Segments of every path between different bodies, and the constant remainder."""

    def __init__(self, ms: MuscleSet, body_index: dict, centroids: np.ndarray):
        self.nm = ms.n
        self.c = np.asarray(centroids, float)
        seg_m, seg_a, seg_b, sa, sb = [], [], [], [], []
        const = np.zeros(ms.n)
        for i, sites in enumerate(ms.sites):
            for (ba, pa), (bb, pb) in zip(sites[:-1], sites[1:]):
                ia, ib = body_index[ba], body_index[bb]
                if ia == ib:                      # same body, or both fixed
                    const[i] += np.linalg.norm(pa - pb)
                    continue
                seg_m.append(i)
                seg_a.append(ia)
                seg_b.append(ib)
                sa.append(pa)
                sb.append(pb)
        self.seg_m = np.array(seg_m, int)
        self.seg_a = np.array(seg_a, int)
        self.seg_b = np.array(seg_b, int)
        self.sa = np.array(sa, float).reshape(-1, 3)
        self.sb = np.array(sb, float).reshape(-1, 3)
        self.const = const
        self.ns = len(seg_m)
        self.M = np.zeros((self.nm, self.ns))
        self.M[self.seg_m, np.arange(self.ns)] = 1.0

    def _attach(self, x, R, idx, s):
        B = x.shape[0]
        p = np.broadcast_to(s, (B,) + s.shape).copy()
        r = np.zeros_like(p)
        for b in np.unique(idx):
            if b < 0:
                continue
            sel = idx == b
            r[:, sel] = (s[sel] - self.c[b]) @ np.swapaxes(R[:, b], -1, -2)
            p[:, sel] = x[:, b, None, :] + r[:, sel]
        return p, r

    def lengths(self, x, R, gradient=True):
        """Path lengths (B, nm) and, optionally, dL/dq (B, nm, nb, 6): compiled (:mod:`lumbar.muscles.compiled`)
        when the solver kernel is active, else :meth:`lengths_reference`."""
        if not kernel.active():
            return self.lengths_reference(x, R, gradient)
        x, R = np.ascontiguousarray(x, float), np.ascontiguousarray(R, float)
        B, nb = x.shape[0], x.shape[1]
        L = np.empty((B, self.nm))
        G = np.zeros((B, self.nm, nb, 6) if gradient else (1, 1, 1, 6))
        compiled.path_lengths(x, R, self.c, self.seg_m, self.seg_a, self.seg_b, self.sa, self.sb, self.const,
                              bool(gradient), L, G)
        return L, (G if gradient else None)

    def lengths_reference(self, x, R, gradient=True):
        """The numpy reference of :meth:`lengths`."""
        pa, ra = self._attach(x, R, self.seg_a, self.sa)
        pb, rb = self._attach(x, R, self.seg_b, self.sb)
        d = pa - pb
        ln = np.linalg.norm(d, axis=-1)
        L = ln @ self.M.T + self.const
        if not gradient:
            return L, None
        u = d / ln[..., None]
        B, nb = x.shape[0], x.shape[1]
        G = np.zeros((B, self.nm, nb, 6))
        ga = np.concatenate([u, np.cross(ra, u)], axis=-1)
        gb = -np.concatenate([u, np.cross(rb, u)], axis=-1)
        for side, g in enumerate((ga, gb)):
            for b, sel, S in self._scatter[side]:       # G[:, m, b] += sum of the muscle's segments on b
                G[:, :, b] += S @ g[:, sel]
        return L, G

    @property
    def _scatter(self):
        """Per path end (a, b) and body: (body, segments, muscle-by-segment indicator) to sum the segments'
        length gradients into their muscles by matrix products (cached; np.add.at was 4x slower)."""
        if self.__dict__.get("_scatter_cache") is None:
            out = []
            for idx in (self.seg_a, self.seg_b):
                lst = []
                for b in np.unique(idx[idx >= 0]):
                    sel = np.flatnonzero(idx == b)
                    S = np.zeros((self.nm, sel.size))
                    S[self.seg_m[sel], np.arange(sel.size)] = 1.0
                    lst.append((int(b), sel, S))
                out.append(lst)
            self._scatter_cache = out
        return self._scatter_cache

    def reference_lengths(self, nb):
        x = self.c[None].copy()
        R = np.broadcast_to(np.eye(3), (1, nb, 3, 3)).copy()
        return self.lengths(x, R, gradient=False)[0][0]
