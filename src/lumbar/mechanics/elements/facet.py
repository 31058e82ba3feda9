"""Facet joints (paper 1, Eqs. 4-5): cubic regression surface and normal penalty contact.

Surface (Eq. 4) in a local frame (u, v, w) fitted to the landmarks:
``w = f(u, v) = p30 u^3 + p03 v^3 + p20 u^2 + p02 v^2 + p00`` (lengths in m).
The local frame is the principal-axis frame of all 18 landmarks (w = least-variance axis,
oriented from the lower vertebra's superior articular process towards the upper vertebra's
inferior articular process). The superior and inferior landmark sets are fitted separately
by least squares and the joint surface is their mean (coefficient-wise), as in the paper.

Contact: the surface moves with the lower vertebra; the upper vertebra's inferior-process
landmarks are the contact points. Gap ``g = w - f(u, v)``; penetration ``delta = -g``.
Normal force magnitude (Eq. 5 without damping), smoothed over ``eps`` for Newton's sake:
``0`` (delta <= 0), ``k delta^2 / (2 eps)`` (0 < delta < eps), ``k (delta - eps/2)`` beyond,
applied along grad g (the surface normal, not normalised: |grad g| = 1 + O(slope^2)).
The joint stiffness ``k`` [N/m] is shared equally by the contact points.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _basis(u, v):
    return np.stack([u**3, v**3, u**2, v**2, np.ones_like(u)], axis=-1)


@dataclass(frozen=True)
class FacetSurface:
    origin: np.ndarray      # (3,) reference-frame origin of the local frame [m]
    axes: np.ndarray        # (3, 3) rows u, v, w (unit) in the reference frame
    coef: np.ndarray        # (5,) p30, p03, p20, p02, p00 of the mean surface [SI]
    coef_superior: np.ndarray
    coef_inferior: np.ndarray
    u_range: tuple
    v_range: tuple
    rms_m: float            # rms distance of the landmarks from their own fitted surface

    def local(self, P):
        """Local (u, v, w) coordinates of reference-frame points P (..., 3)."""
        return (np.asarray(P, float) - self.origin) @ self.axes.T

    def surface(self, u, v):
        p30, p03, p20, p02, p00 = self.coef
        f = p30 * u**3 + p03 * v**3 + p20 * u**2 + p02 * v**2 + p00
        fu = 3 * p30 * u**2 + 2 * p20 * u
        fv = 3 * p03 * v**2 + 2 * p02 * v
        fuu = 6 * p30 * u + 2 * p20
        fvv = 6 * p03 * v + 2 * p02
        return f, fu, fv, fuu, fvv

    def gap(self, P, hessian=True):
        """Gap g (...,), gradient dg/dP (..., 3) and Hessian (..., 3, 3) in the reference frame (None without
        ``hessian``: g and the gradient are the same numbers either way)."""
        q = self.local(P)
        f, fu, fv, fuu, fvv = self.surface(q[..., 0], q[..., 1])
        g = q[..., 2] - f
        grad_q = np.stack([-fu, -fv, np.ones_like(fu)], axis=-1)
        if not hessian:
            return g, grad_q @ self.axes, None
        hess_q = np.zeros(q.shape[:-1] + (3, 3))
        hess_q[..., 0, 0] = -fuu
        hess_q[..., 1, 1] = -fvv
        grad = grad_q @ self.axes
        hess = self.axes.T @ hess_q @ self.axes
        return g, grad, hess

    def beyond_extent(self, P, margin=0.0):
        """True where reference-frame points P (..., 3) lie outside the landmarks' (u, v) extent grown by ``margin``
        [m]: there the Eq. 4 surface is an extrapolation of its regression, outside the law's validity (no
        articular surface was fitted there)."""
        q = self.local(P)
        (u0, u1), (v0, v1) = self.u_range, self.v_range
        return ((q[..., 0] < u0 - margin) | (q[..., 0] > u1 + margin)
                | (q[..., 1] < v0 - margin) | (q[..., 1] > v1 + margin))

    def grid(self, n=12):
        """(n, n, 3) reference-frame points of the mean surface over the landmark extent."""
        u = np.linspace(*self.u_range, n)
        v = np.linspace(*self.v_range, n)
        U, V = np.meshgrid(u, v, indexing="ij")
        W = self.surface(U, V)[0]
        return self.origin + np.stack([U, V, W], axis=-1) @ self.axes


CONTACT_RULES = ("mean_surface", "touching")


def fit_surface(superior, inferior, medial_hint=None, contact="mean_surface", contact_points=None) -> FacetSurface:
    """Fit Eq. 4 to the nine landmarks of each articular process and average the two fits.

    ``contact``: "mean_surface" (the paper's rule: the joint surface is the coefficient mean of the two
    fits) or "touching" (the mean surface shifted along w so that the upper-process landmark nearest to it
    lies on it: gap 0 at rest, no landmark penetrating; for landmarks on the two bone faces of a
    cartilage-filled joint, see ``lumbar.geometry.core.FacetLandmarks``).

    ``superior``: (n, 3) landmarks on the lower vertebra's superior articular process;
    ``inferior``: (n, 3) on the upper vertebra's inferior articular process (reference frame).
    ``medial_hint``: unit vector used to orient w when the two sets are not separated.
    ``contact_points``: the points of the upper face that touch the surface (default ``inferior``): the "touching"
    rule puts the nearest of them on the surface.
    """
    S = np.asarray(superior, float)
    I = np.asarray(inferior, float)  # noqa: E741 - S/I: superior/inferior landmarks, as in the paper
    if S.shape[0] < 5 or I.shape[0] < 5 or S.shape[1:] != (3,) or I.shape[1:] != (3,):
        raise ValueError(f"facet landmarks must be (n>=5, 3) arrays, got {S.shape} and {I.shape}")
    allp = np.vstack([S, I])
    origin = allp.mean(axis=0)
    _, _, vt = np.linalg.svd(allp - origin)
    u, v, w = vt[0], vt[1], vt[2]
    sep = (I.mean(0) - S.mean(0)) @ w
    if abs(sep) > 1e-4 or medial_hint is None:
        if sep < 0:
            w = -w
    elif np.dot(w, medial_hint) < 0:
        w = -w
    if u[2] < 0:  # deterministic in-plane orientation: u tends superior
        u = -u
    v = np.cross(w, u)
    axes = np.vstack([u, v, w])
    coefs, rms = [], []
    for pts in (S, I):
        q = (pts - origin) @ axes.T
        A = _basis(q[:, 0], q[:, 1])
        c, *_ = np.linalg.lstsq(A, q[:, 2], rcond=None)
        coefs.append(c)
        rms.append(np.sqrt(np.mean((A @ c - q[:, 2]) ** 2)))
    q_all = (allp - origin) @ axes.T
    coef = 0.5 * (coefs[0] + coefs[1])
    if contact == "touching":
        qi = ((I if contact_points is None else np.asarray(contact_points, float)) - origin) @ axes.T
        gap = qi[:, 2] - _basis(qi[:, 0], qi[:, 1]) @ coef
        coef = coef.copy()
        coef[4] += float(gap.min())
    elif contact != "mean_surface":
        raise ValueError(f"facet contact rule {contact!r}; expected one of {CONTACT_RULES}")
    return FacetSurface(
        origin=origin, axes=axes, coef=coef,
        coef_superior=coefs[0], coef_inferior=coefs[1],
        u_range=(q_all[:, 0].min(), q_all[:, 0].max()),
        v_range=(q_all[:, 1].min(), q_all[:, 1].max()),
        rms_m=float(max(rms)),
    )


def contact_penalty(delta, k, eps):
    """Smoothed linear penalty: force magnitude [N] and d/d delta [N/m] for penetration delta [m]."""
    delta = np.asarray(delta, float)
    quad = (delta > 0) & (delta < eps)
    lin = delta >= eps
    F = np.where(quad, k * delta**2 / (2 * eps), 0.0) + np.where(lin, k * (delta - eps / 2), 0.0)
    dF = np.where(quad, k * delta / eps, 0.0) + np.where(lin, k, 0.0)
    return F, dF
