"""Compiled residual and Jacobian of the equilibrium solver, scenario by scenario (numba; the switch, the packing
of the model's arrays and the Newton iteration are :mod:`lumbar.mechanics.kernel`, the only module that calls this
one).

Per scenario (:func:`eval_one`): the ligament fibres, the facet contact and the discs, each a compiled step of its own,
from the same formulas as the numpy reference path (:meth:`lumbar.mechanics.model.SpineModel.evaluate_reference`),
element by element: the SO(3) maps, the assembly of a force and of its 3x3 stiffness into Q and J, the fibre laws
(:func:`_tension`), the discs' torque laws (Eq. 3 and cubic_deg) and the screen of open contact points (:data:`SCREEN_M`).
:func:`evaluate_batch` is the compiled ``SpineModel.evaluate`` of a batch.
"""
from __future__ import annotations

import numpy as np

from .elements.ligament import LAW_CABLE, LAW_RUPP, LAW_SOFTPLUS  # noqa: F401 - compile-time constants
from .jit import leaf_jit as _inner
from .jit import inline_leaf_jit as _inline
from .jit import jit as _jit

#: a contact point whose screened gap (the affine map of _screen_map; it differs from the exact one by round-off,
#: about 1e-15 m on these coordinates) exceeds SCREEN_M is open and skipped; every other point is evaluated exactly
SCREEN_M = 1e-9
#: degrees per radian (the ``cubic_deg`` torque law's angle unit; lumbar.mechanics.elements.disc._DEG)
DEG = 180.0 / np.pi
#: the disc torque laws' codes in column 4 of the discs' stiffness rows (kernel.model_data): Eq. 3 and cubic_deg
DISC_LAW_EQ3, DISC_LAW_CUBIC_DEG = 0.0, 1.0


# ---------------------------------------------------------------------------------------------------- SO(3)
@_inner
def rotation_exp(w, out):
    """Rotation matrix of rotation vector w (as scipy's Rotation.from_rotvec(w).as_matrix())."""
    angle = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
    else:
        scale = np.sin(angle / 2.0) / angle
    x, y, z, q = scale * w[0], scale * w[1], scale * w[2], np.cos(angle / 2.0)
    x2, y2, z2, w2 = x * x, y * y, z * z, q * q
    xy, zw, xz, yw, yz, xw = x * y, z * q, x * z, y * q, y * z, x * q
    out[0, 0] = x2 - y2 - z2 + w2
    out[1, 0] = 2.0 * (xy + zw)
    out[2, 0] = 2.0 * (xz - yw)
    out[0, 1] = 2.0 * (xy - zw)
    out[1, 1] = -x2 + y2 - z2 + w2
    out[2, 1] = 2.0 * (yz + xw)
    out[0, 2] = 2.0 * (xz + yw)
    out[1, 2] = 2.0 * (yz - xw)
    out[2, 2] = -x2 - y2 + z2 + w2


@_inner
def rotation_log(Rm, out, out4):
    """Rotation vector of rotation matrix Rm (quaternion route, as scipy's Rotation.from_matrix().as_rotvec())."""
    q = out4
    tr = Rm[0, 0] + Rm[1, 1] + Rm[2, 2]
    choice = 3
    best = tr
    for i in range(3):
        if Rm[i, i] > best:
            best = Rm[i, i]
            choice = i
    if choice != 3:
        i = choice
        j = (i + 1) % 3
        k = (j + 1) % 3
        q[i] = 1.0 - tr + 2.0 * Rm[i, i]
        q[j] = Rm[j, i] + Rm[i, j]
        q[k] = Rm[k, i] + Rm[i, k]
        q[3] = Rm[k, j] - Rm[j, k]
    else:
        q[0] = Rm[2, 1] - Rm[1, 2]
        q[1] = Rm[0, 2] - Rm[2, 0]
        q[2] = Rm[1, 0] - Rm[0, 1]
        q[3] = 1.0 + tr
    nq = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for i in range(4):
        q[i] /= nq
    if q[3] < 0.0:
        for i in range(4):
            q[i] = -q[i]
    angle = 2.0 * np.arctan2(np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]), q[3])
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0
    else:
        scale = angle / np.sin(angle / 2.0)
    for i in range(3):
        out[i] = scale * q[i]


@_inner
def _jl_inv(phi, out, work):
    """Inverse left Jacobian of SO(3) at phi (lumbar.mechanics.so3.left_jacobian_inverse)."""
    theta = np.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
    if theta < 1e-4:
        coef = 1.0 / 12.0 + theta ** 2 / 720.0
    else:
        coef = 1.0 / theta ** 2 - (1.0 + np.cos(theta)) / (2.0 * theta * np.sin(theta))
    K = work
    K[0, 0], K[1, 1], K[2, 2] = 0.0, 0.0, 0.0
    K[0, 1], K[0, 2], K[1, 0] = -phi[2], phi[1], phi[2]
    K[1, 2], K[2, 0], K[2, 1] = -phi[0], -phi[1], phi[0]
    for i in range(3):
        for j in range(3):
            k2 = K[i, 0] * K[0, j] + K[i, 1] * K[1, j] + K[i, 2] * K[2, j]
            out[i, j] = (1.0 if i == j else 0.0) - 0.5 * K[i, j] + coef * k2


# ---------------------------------------------------------------------------------------------------- assembly
@_inner
def _attach(x, R, c, body, S, row, p, r):
    """World point p of body-fixed reference point S[row] on ``body`` and its lever arm r about the body's point
    (the point itself for ground)."""
    if body < 0:
        for i in range(3):
            p[i] = S[row, i]
            r[i] = S[row, i]
    else:
        s0, s1, s2 = S[row, 0] - c[body, 0], S[row, 1] - c[body, 1], S[row, 2] - c[body, 2]
        for i in range(3):
            r[i] = R[body, i, 0] * s0 + R[body, i, 1] * s1 + R[body, i, 2] * s2
            p[i] = x[body, i] + r[i]


@_inner
def _point(x, R, c, body, S, row):
    """(p, r) as six scalars: world point of reference point S[row] on ``body`` and its lever arm (see _attach)."""
    if body < 0:
        return S[row, 0], S[row, 1], S[row, 2], S[row, 0], S[row, 1], S[row, 2]
    s0, s1, s2 = S[row, 0] - c[body, 0], S[row, 1] - c[body, 1], S[row, 2] - c[body, 2]
    r0 = R[body, 0, 0] * s0 + R[body, 0, 1] * s1 + R[body, 0, 2] * s2
    r1 = R[body, 1, 0] * s0 + R[body, 1, 1] * s1 + R[body, 1, 2] * s2
    r2 = R[body, 2, 0] * s0 + R[body, 2, 1] * s1 + R[body, 2, 2] * s2
    return x[body, 0] + r0, x[body, 1] + r1, x[body, 2] + r2, r0, r1, r2


@_inner
def _frame_coords(P, o, A):
    """Coordinates of point P in the frame with origin o and rows A (the rows' directions)."""
    d0, d1, d2 = P[0] - o[0], P[1] - o[1], P[2] - o[2]
    return (d0 * A[0, 0] + d1 * A[0, 1] + d2 * A[0, 2], d0 * A[1, 0] + d1 * A[1, 1] + d2 * A[1, 2],
            d0 * A[2, 0] + d1 * A[2, 1] + d2 * A[2, 2])


@_inner
def _in_body(x, R, c, body, p0, p1, p2):
    """(lever arm of world point p about ``body``'s reference point, reference-frame coordinates of p in ``body``)
    as six scalars (see _lever, _to_body)."""
    if body < 0:
        return p0, p1, p2, p0, p1, p2
    e0, e1, e2 = p0 - x[body, 0], p1 - x[body, 1], p2 - x[body, 2]
    return (e0, e1, e2, R[body, 0, 0] * e0 + R[body, 1, 0] * e1 + R[body, 2, 0] * e2 + c[body, 0],
            R[body, 0, 1] * e0 + R[body, 1, 1] * e1 + R[body, 2, 1] * e2 + c[body, 1],
            R[body, 0, 2] * e0 + R[body, 1, 2] * e1 + R[body, 2, 2] * e2 + c[body, 2])


@_inner
def _lever(x, body, p, r):
    """Lever arm of world point p about ``body``'s reference point (the point itself for ground)."""
    for i in range(3):
        r[i] = p[i] if body < 0 else p[i] - x[body, i]


@_inner
def _to_body(x, R, c, body, p, P):
    """Reference-frame coordinates in ``body`` of world point p."""
    if body < 0:
        for i in range(3):
            P[i] = p[i]
    else:
        for i in range(3):
            P[i] = (R[body, 0, i] * (p[0] - x[body, 0]) + R[body, 1, i] * (p[1] - x[body, 1])
                    + R[body, 2, i] * (p[2] - x[body, 2])) + c[body, i]


@_inner
def _relative_point(x, R, c, a, b, S, row, p, ra, rb, P):
    """Point S[row] carried by body a: world point p, its lever arms ra, rb about bodies a and b, and its
    reference-frame coordinates P in body b (where a law fixed in body b reads it)."""
    _attach(x, R, c, a, S, row, p, ra)
    _lever(x, b, p, rb)
    _to_body(x, R, c, b, p, P)


@_inner
def _rot(R, body, v, out):
    if body < 0:
        for i in range(3):
            out[i] = v[i]
    else:
        for i in range(3):
            out[i] = R[body, i, 0] * v[0] + R[body, i, 1] * v[1] + R[body, i, 2] * v[2]


@_inner
def _add_force(Q, body, f, r, sign):
    if body >= 0:
        Q[body, 0] += sign * f[0]
        Q[body, 1] += sign * f[1]
        Q[body, 2] += sign * f[2]
        Q[body, 3] += sign * (r[1] * f[2] - r[2] * f[1])
        Q[body, 4] += sign * (r[2] * f[0] - r[0] * f[2])
        Q[body, 5] += sign * (r[0] * f[1] - r[1] * f[0])


@_inner
def _add_gkg(J, bi, bj, K, r1, r2, sign):
    """J[bi, :, bj, :] += sign * G1 K G2^T with G = [I; [r]x]:
    [[K, -K [r2]x], [[r1]x K, -[r1]x K [r2]x]]."""
    for rr in range(3):
        # row rr of [r1]x K is (r1 x K[:, c])[rr] for each column c; row rr of -K [r2]x is r2 x K[rr, :] and of
        # -[r1]x K [r2]x is r2 x ([r1]x K)[rr, :]
        i1, i2 = (rr + 1) % 3, (rr + 2) % 3
        k0, k1, k2 = K[rr, 0], K[rr, 1], K[rr, 2]
        m0 = r1[i1] * K[i2, 0] - r1[i2] * K[i1, 0]
        m1 = r1[i1] * K[i2, 1] - r1[i2] * K[i1, 1]
        m2 = r1[i1] * K[i2, 2] - r1[i2] * K[i1, 2]
        J[bi, rr, bj, 0] += sign * k0
        J[bi, rr, bj, 1] += sign * k1
        J[bi, rr, bj, 2] += sign * k2
        J[bi, rr, bj, 3] += sign * (r2[1] * k2 - r2[2] * k1)
        J[bi, rr, bj, 4] += sign * (r2[2] * k0 - r2[0] * k2)
        J[bi, rr, bj, 5] += sign * (r2[0] * k1 - r2[1] * k0)
        J[bi, 3 + rr, bj, 0] += sign * m0
        J[bi, 3 + rr, bj, 1] += sign * m1
        J[bi, 3 + rr, bj, 2] += sign * m2
        J[bi, 3 + rr, bj, 3] += sign * (r2[1] * m2 - r2[2] * m1)
        J[bi, 3 + rr, bj, 4] += sign * (r2[2] * m0 - r2[0] * m2)
        J[bi, 3 + rr, bj, 5] += sign * (r2[0] * m1 - r2[1] * m0)


@_inner
def _add_hatprod(J, bi, bj, a, b, sign):
    """J[bi, 3:, bj, 3:] += sign * [a]x [b]x = sign * (b a^T - (a.b) I)."""
    ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    for i in range(3):
        for j in range(3):
            J[bi, 3 + i, bj, 3 + j] += sign * (b[i] * a[j] - (ab if i == j else 0.0))


@_inner
def _add_hat(J, bi, bj, f, sign, o1, o2):
    """J[bi, o1:o1+3, bj, o2:o2+3] += sign * [f]x."""
    J[bi, o1 + 0, bj, o2 + 1] += -sign * f[2]
    J[bi, o1 + 0, bj, o2 + 2] += sign * f[1]
    J[bi, o1 + 1, bj, o2 + 0] += sign * f[2]
    J[bi, o1 + 1, bj, o2 + 2] += -sign * f[0]
    J[bi, o1 + 2, bj, o2 + 0] += -sign * f[1]
    J[bi, o1 + 2, bj, o2 + 1] += sign * f[0]


@_inner
def _fibre_block(J, bi, bj, sign, beta, alpha, u, p, q, hsign, f):
    """J[bi, :, bj, :] += sign * G1 K G2^T for a fibre's K = beta u u^T + alpha I (G = [I; [r]x], r1 = p of body
    bi, r2 = q of body bj): beta g1 g2^T with g = (u, r x u), plus alpha [[I, -[q]x], [[p]x, (p.q) I - q p^T]]
    (the same block as _add_gkg, from scalars); then, where ``hsign`` is not 0 (a diagonal block, p = q = r), the
    fibre's geometric stiffness J[bi, 3:, bi, 3:] += hsign * [f]x [r]x = hsign * (r f^T - (f.r) I). Each entry is
    read and written once, its terms added in this order."""
    g1 = (u[0], u[1], u[2], p[1] * u[2] - p[2] * u[1], p[2] * u[0] - p[0] * u[2], p[0] * u[1] - p[1] * u[0])
    g2 = (u[0], u[1], u[2], q[1] * u[2] - q[2] * u[1], q[2] * u[0] - q[0] * u[2], q[0] * u[1] - q[1] * u[0])
    sb, sa = sign * beta, sign * alpha
    pq = p[0] * q[0] + p[1] * q[1] + p[2] * q[2]
    fr = f[0] * q[0] + f[1] * q[1] + f[2] * q[2]
    # -[q]x and [p]x by rows
    mq = ((0.0, q[2], -q[1]), (-q[2], 0.0, q[0]), (q[1], -q[0], 0.0))
    hp = ((0.0, -p[2], p[1]), (p[2], 0.0, -p[0]), (-p[1], p[0], 0.0))
    for k in range(3):
        for m in range(3):
            v = J[bi, k, bj, m] + sb * g1[k] * g2[m]
            if k == m:
                v += sa
            J[bi, k, bj, m] = v
            v = J[bi, k, bj, 3 + m] + sb * g1[k] * g2[3 + m]
            if k != m:
                v += sa * mq[k][m]
            J[bi, k, bj, 3 + m] = v
            v = J[bi, 3 + k, bj, m] + sb * g1[3 + k] * g2[m]
            if k != m:
                v += sa * hp[k][m]
            J[bi, 3 + k, bj, m] = v
            v = J[bi, 3 + k, bj, 3 + m] + sb * g1[3 + k] * g2[3 + m]
            if k == m:
                v += sa * pq
            v -= sa * q[k] * p[m]
            if hsign != 0.0:
                if k == m:
                    v -= hsign * fr
                v += hsign * q[k] * f[m]
            J[bi, 3 + k, bj, 3 + m] = v


@_inner
def _assemble_j(J, a, b, f, ra, rb, K, body_relative):
    """Jacobian blocks of one point element with force f on body a (lever ra), -f on body b (lever rb) and
    stiffness K = df/dp (world); ``body_relative``: the law is fixed in body b (facets, disc translation)."""
    if a >= 0:
        _add_gkg(J, a, a, K, ra, ra, 1.0)
        _add_hatprod(J, a, a, f, ra, 1.0)
    if b >= 0:
        _add_gkg(J, b, b, K, rb, rb, 1.0)
        if body_relative:
            _add_hat(J, b, b, f, 1.0, 0, 3)
            _add_hat(J, b, b, f, -1.0, 3, 0)
            _add_hatprod(J, b, b, rb, f, 1.0)
        else:
            _add_hatprod(J, b, b, f, rb, -1.0)
    if a >= 0 and b >= 0:
        _add_gkg(J, a, b, K, ra, rb, -1.0)
        _add_gkg(J, b, a, K, rb, ra, -1.0)
        if body_relative:
            _add_hat(J, a, b, f, -1.0, 0, 3)
            _add_hatprod(J, a, b, ra, f, -1.0)
            _add_hat(J, b, a, f, 1.0, 3, 0)
            _add_hatprod(J, b, a, f, ra, -1.0)


@_inner
def _assemble(Q, J, jac, a, b, f, ra, rb, K, body_relative):
    """One point element (see SpineModel._assemble of the reference path)."""
    _add_force(Q, a, f, ra, 1.0)
    _add_force(Q, b, f, rb, -1.0)
    if jac:
        _assemble_j(J, a, b, f, ra, rb, K, body_relative)


@_inner
def _rot3(R, body, v0, v1, v2):
    """R[body] v as three scalars (v itself for ground; _rot without arrays)."""
    if body < 0:
        return v0, v1, v2
    return (R[body, 0, 0] * v0 + R[body, 0, 1] * v1 + R[body, 0, 2] * v2,
            R[body, 1, 0] * v0 + R[body, 1, 1] * v1 + R[body, 1, 2] * v2,
            R[body, 2, 0] * v0 + R[body, 2, 1] * v1 + R[body, 2, 2] * v2)


@_inner
def _screen_map(x, R, c, a, b, orig, ax):
    """Affine map (G, t) from a point's reference coordinates S - c_a on body ``a`` (S on ground) to its coordinates
    (u, v, w) in the frame (origin ``orig``, rows ``ax``) of a surface fixed in body ``b``: the composition of _point,
    _in_body and the surface frame, G = ax R_b^T R_a, t = ax (R_b^T (x_a - x_b) + c_b - orig); twelve scalars, G by
    rows, then t."""
    # A = ax R_b^T (ax for ground), then G = A R_a (A for ground)
    a00, a01, a02 = ax[0, 0], ax[0, 1], ax[0, 2]
    a10, a11, a12 = ax[1, 0], ax[1, 1], ax[1, 2]
    a20, a21, a22 = ax[2, 0], ax[2, 1], ax[2, 2]
    e0 = x[a, 0] if a >= 0 else 0.0
    e1 = x[a, 1] if a >= 0 else 0.0
    e2 = x[a, 2] if a >= 0 else 0.0
    if b >= 0:
        e0, e1, e2 = e0 - x[b, 0], e1 - x[b, 1], e2 - x[b, 2]
        d0 = R[b, 0, 0] * e0 + R[b, 1, 0] * e1 + R[b, 2, 0] * e2 + c[b, 0] - orig[0]
        d1 = R[b, 0, 1] * e0 + R[b, 1, 1] * e1 + R[b, 2, 1] * e2 + c[b, 1] - orig[1]
        d2 = R[b, 0, 2] * e0 + R[b, 1, 2] * e1 + R[b, 2, 2] * e2 + c[b, 2] - orig[2]
        Rb = R[b]
        a00, a01, a02 = (a00 * Rb[0, 0] + a01 * Rb[0, 1] + a02 * Rb[0, 2], a00 * Rb[1, 0] + a01 * Rb[1, 1]
                         + a02 * Rb[1, 2], a00 * Rb[2, 0] + a01 * Rb[2, 1] + a02 * Rb[2, 2])
        a10, a11, a12 = (a10 * Rb[0, 0] + a11 * Rb[0, 1] + a12 * Rb[0, 2], a10 * Rb[1, 0] + a11 * Rb[1, 1]
                         + a12 * Rb[1, 2], a10 * Rb[2, 0] + a11 * Rb[2, 1] + a12 * Rb[2, 2])
        a20, a21, a22 = (a20 * Rb[0, 0] + a21 * Rb[0, 1] + a22 * Rb[0, 2], a20 * Rb[1, 0] + a21 * Rb[1, 1]
                         + a22 * Rb[1, 2], a20 * Rb[2, 0] + a21 * Rb[2, 1] + a22 * Rb[2, 2])
    else:
        d0, d1, d2 = e0 - orig[0], e1 - orig[1], e2 - orig[2]
    t0 = ax[0, 0] * d0 + ax[0, 1] * d1 + ax[0, 2] * d2
    t1 = ax[1, 0] * d0 + ax[1, 1] * d1 + ax[1, 2] * d2
    t2 = ax[2, 0] * d0 + ax[2, 1] * d1 + ax[2, 2] * d2
    if a >= 0:
        Ra = R[a]
        return (a00 * Ra[0, 0] + a01 * Ra[1, 0] + a02 * Ra[2, 0], a00 * Ra[0, 1] + a01 * Ra[1, 1] + a02 * Ra[2, 1],
                a00 * Ra[0, 2] + a01 * Ra[1, 2] + a02 * Ra[2, 2],
                a10 * Ra[0, 0] + a11 * Ra[1, 0] + a12 * Ra[2, 0], a10 * Ra[0, 1] + a11 * Ra[1, 1] + a12 * Ra[2, 1],
                a10 * Ra[0, 2] + a11 * Ra[1, 2] + a12 * Ra[2, 2],
                a20 * Ra[0, 0] + a21 * Ra[1, 0] + a22 * Ra[2, 0], a20 * Ra[0, 1] + a21 * Ra[1, 1] + a22 * Ra[2, 1],
                a20 * Ra[0, 2] + a21 * Ra[1, 2] + a22 * Ra[2, 2], t0, t1, t2)
    return a00, a01, a02, a10, a11, a12, a20, a21, a22, t0, t1, t2


@_inner
def _tension(law, length, l0, P, row, width):
    """Fibre law value and derivative d/d(length) before the fibre's scale (SpineModel._tension_raw); the law's
    parameters are row ``row`` of P."""
    par0, par1, par2, par3, par4 = P[row, 0], P[row, 1], P[row, 2], P[row, 3], P[row, 4]
    if law == LAW_SOFTPLUS:
        eps = (length / l0 - 1.0) * 100.0
        if eps <= 0.0:
            return 0.0, 0.0
        z = (eps + par1) / par3
        e = np.exp(-abs(z))                  # softplus and its derivative, the logistic function, from one exp
        F = par0 * (max(z, 0.0) + np.log1p(e)) + par2
        dF = par0 / par3 * (1.0 / (1.0 + e) if z >= 0.0 else e / (1.0 + e))
        if not F > 0.0:
            F, dF = 0.0, 0.0
        if width <= 0.0:
            s, ds = 1.0, 0.0
        else:
            t = min(eps / width, 1.0)
            s = t * t * (3.0 - 2.0 * t)
            ds = 6.0 * t * (1.0 - t) / width if eps < width else 0.0
        return s * F, (ds * F + s * dF) * 100.0 / l0
    if law == LAW_RUPP:
        dl = length - l0
        if dl > 0.0 and dl < par0:
            return par3 * dl ** par2, par2 * par3 * dl ** (par2 - 1.0)
        if dl >= par0:
            return par1 + par4 * (dl - par0), par4
        return 0.0, 0.0
    return par0, 0.0


@_inner
def _torque_angle(phi, p):
    z = phi ** 3 / p[1]
    t = np.tanh(z)
    return p[0] * t + p[2] * phi, p[0] * (1.0 - t ** 2) * 3.0 * phi ** 2 / p[1] + p[2]


@_inner
def _torque_cubic_deg(phi, p):
    """The ``cubic_deg`` law (lumbar.mechanics.elements.disc.torque_cubic_deg, the same operations): torque [N*m]
    and its derivative [N*m/rad] at ``phi`` [rad]."""
    d = abs(phi) * DEG
    return (p[0] * d * d + p[1] * d + p[2]) * phi * DEG, (3.0 * p[0] * d * d + 2.0 * p[1] * d + p[2]) * DEG


@_inner
def _torque(phi, p, cubic):
    if cubic:
        return _torque_cubic_deg(phi, p)
    return _torque_angle(phi, p)

# The residual and Jacobian of one scenario, in three named steps (fibres, facet contact, discs); each step is one
# compiled function, called once per scenario (their loops run inside: the cost of the calls is nothing beside them).
#: accumulators of one body's diagonal Jacobian block from its fibre ends (_acc_end): sum beta g g^T (21, upper triangle
#: by rows), sum alpha (1), sum alpha r (3), sum alpha r r^T (6: xx, xy, xz, yy, yz, zz), sum s r f^T (9, by rows)
ACC = 40


@_inner
def _acc_end(acc, k, beta, alpha, u0, u1, u2, r0, r1, r2, s, f0, f1, f2):
    """Add one fibre end on body k (lever r, fibre stiffness K = beta u u^T + alpha I, force f on the fibre's body a,
    the end's sign s: +1 at a, -1 at b) to body k's accumulators: its block G K G^T with G = [I; [r]x] is
    beta g g^T (g = (u, r x u)) + alpha [[I, -[r]x], [[r]x, (r.r) I - r r^T]], and its geometric stiffness
    s (r f^T - (f.r) I) (_fibre_block with p = q = r)."""
    g = (u0, u1, u2, r1 * u2 - r2 * u1, r2 * u0 - r0 * u2, r0 * u1 - r1 * u0)
    m = 0
    for i in range(6):
        bi = beta * g[i]
        for j in range(i, 6):
            acc[k, m] += bi * g[j]
            m += 1
    acc[k, 21] += alpha
    ar0, ar1, ar2 = alpha * r0, alpha * r1, alpha * r2
    acc[k, 22] += ar0
    acc[k, 23] += ar1
    acc[k, 24] += ar2
    acc[k, 25] += ar0 * r0
    acc[k, 26] += ar0 * r1
    acc[k, 27] += ar0 * r2
    acc[k, 28] += ar1 * r1
    acc[k, 29] += ar1 * r2
    acc[k, 30] += ar2 * r2
    sr0, sr1, sr2 = s * r0, s * r1, s * r2
    acc[k, 31] += sr0 * f0
    acc[k, 32] += sr0 * f1
    acc[k, 33] += sr0 * f2
    acc[k, 34] += sr1 * f0
    acc[k, 35] += sr1 * f1
    acc[k, 36] += sr1 * f2
    acc[k, 37] += sr2 * f0
    acc[k, 38] += sr2 * f1
    acc[k, 39] += sr2 * f2


@_inner
def _acc_point(acc, k, w0, w1, w2, a0, a1, a2, b0, b1, b2, c0, c1, c2, r0, r1, r2, f0, f1, f2):
    """Add a point element on body k against the ground (a facet contact point) to body k's accumulators (_acc_end):
    its stiffness K = w0 a a^T + w1 b b^T + w2 c c^T (world vectors a, b, c; symmetric) at lever r gives the symmetric
    block G K G^T = [[K, K C^T], [C K, C K C^T]] (C = [r]x), and its force f the geometric stiffness r f^T - (f.r) I
    (_assemble_j with a free body a and b the ground)."""
    K = (w0 * a0 * a0 + w1 * b0 * b0 + w2 * c0 * c0, w0 * a0 * a1 + w1 * b0 * b1 + w2 * c0 * c1,
         w0 * a0 * a2 + w1 * b0 * b2 + w2 * c0 * c2, w0 * a1 * a1 + w1 * b1 * b1 + w2 * c1 * c1,
         w0 * a1 * a2 + w1 * b1 * b2 + w2 * c1 * c2, w0 * a2 * a2 + w1 * b2 * b2 + w2 * c2 * c2)
    k00, k01, k02, k11, k12, k22 = K
    # T = K C^T, T[i][j] = K_i . C_j with the rows of C: (0, -r2, r1), (r2, 0, -r0), (-r1, r0, 0)
    t00, t01, t02 = -r2 * k01 + r1 * k02, r2 * k00 - r0 * k02, -r1 * k00 + r0 * k01
    t10, t11, t12 = -r2 * k11 + r1 * k12, r2 * k01 - r0 * k12, -r1 * k01 + r0 * k11
    t20, t21, t22 = -r2 * k12 + r1 * k22, r2 * k02 - r0 * k22, -r1 * k02 + r0 * k12
    # C T (symmetric): (C T)[i][j] = C_i . T[:, j]
    b00 = -r2 * t10 + r1 * t20
    b01 = -r2 * t11 + r1 * t21
    b02 = -r2 * t12 + r1 * t22
    b11 = r2 * t01 - r0 * t21
    b12 = r2 * t02 - r0 * t22
    b22 = -r1 * t02 + r0 * t12
    acc[k, 0] += k00
    acc[k, 1] += k01
    acc[k, 2] += k02
    acc[k, 3] += t00
    acc[k, 4] += t01
    acc[k, 5] += t02
    acc[k, 6] += k11
    acc[k, 7] += k12
    acc[k, 8] += t10
    acc[k, 9] += t11
    acc[k, 10] += t12
    acc[k, 11] += k22
    acc[k, 12] += t20
    acc[k, 13] += t21
    acc[k, 14] += t22
    acc[k, 15] += b00
    acc[k, 16] += b01
    acc[k, 17] += b02
    acc[k, 18] += b11
    acc[k, 19] += b12
    acc[k, 20] += b22
    acc[k, 31] += r0 * f0
    acc[k, 32] += r0 * f1
    acc[k, 33] += r0 * f2
    acc[k, 34] += r1 * f0
    acc[k, 35] += r1 * f1
    acc[k, 36] += r1 * f2
    acc[k, 37] += r2 * f0
    acc[k, 38] += r2 * f1
    acc[k, 39] += r2 * f2


@_inner
def _acc_to_j(J, acc, k):
    """J[k, :, k, :] += body k's fibre block from its accumulators (_acc_end)."""
    a = acc[k]
    m = 0
    for i in range(6):
        for j in range(i, 6):
            J[k, i, k, j] += a[m]
            if j != i:
                J[k, j, k, i] += a[m]
            m += 1
    sa, p0, p1, p2 = a[21], a[22], a[23], a[24]
    tr_rr = a[25] + a[28] + a[30]
    tr_h = a[31] + a[35] + a[39]
    for i in range(3):
        J[k, i, k, i] += sa
        J[k, 3 + i, k, 3 + i] += tr_rr - tr_h
    # alpha parts: -[p]x upper right, [p]x lower left (p = sum alpha r)
    J[k, 0, k, 4] += p2
    J[k, 0, k, 5] -= p1
    J[k, 1, k, 3] -= p2
    J[k, 1, k, 5] += p0
    J[k, 2, k, 3] += p1
    J[k, 2, k, 4] -= p0
    J[k, 3, k, 1] -= p2
    J[k, 3, k, 2] += p1
    J[k, 4, k, 0] += p2
    J[k, 4, k, 2] -= p0
    J[k, 5, k, 0] -= p1
    J[k, 5, k, 1] += p0
    # lower right: - sum alpha r r^T + sum s r f^T
    rr = ((a[25], a[26], a[27]), (a[26], a[28], a[29]), (a[27], a[29], a[30]))
    for i in range(3):
        for j in range(3):
            J[k, 3 + i, k, 3 + j] += a[31 + 3 * i + j] - rr[i][j]


@_inner
def _fibres(x, R, Q, J, jac, c, f_a, f_b, f_sa, f_sb, f_extra, f_law, f_par, f_scale, width, fm, l0, acc):
    """Ligament fibres: forces into Q and, with ``jac``, the stiffness K = dT u u^T + T/|d| (I - u u^T) (with the
    sign of a pulling element) into J. The attachment points (_point) and the law (_tension) are written out here:
    a call per fibre cost more than the fibre's arithmetic. A fibre's diagonal blocks of J (body a with itself, body b
    with itself) are summed in ``acc`` (nb, ACC) by :func:`_acc_end` and written once by :func:`_acc_to_j`; the blocks
    between two free bodies go to J directly (_fibre_block)."""
    for n in range(f_a.shape[0]):
        a, b = f_a[n], f_b[n]
        if a < 0:
            ra0, ra1, ra2 = f_sa[n, 0], f_sa[n, 1], f_sa[n, 2]
            pa0, pa1, pa2 = ra0, ra1, ra2
        else:
            s0, s1, s2 = f_sa[n, 0] - c[a, 0], f_sa[n, 1] - c[a, 1], f_sa[n, 2] - c[a, 2]
            ra0 = R[a, 0, 0] * s0 + R[a, 0, 1] * s1 + R[a, 0, 2] * s2
            ra1 = R[a, 1, 0] * s0 + R[a, 1, 1] * s1 + R[a, 1, 2] * s2
            ra2 = R[a, 2, 0] * s0 + R[a, 2, 1] * s1 + R[a, 2, 2] * s2
            pa0, pa1, pa2 = x[a, 0] + ra0, x[a, 1] + ra1, x[a, 2] + ra2
        if b < 0:
            rb0, rb1, rb2 = f_sb[n, 0], f_sb[n, 1], f_sb[n, 2]
            pb0, pb1, pb2 = rb0, rb1, rb2
        else:
            s0, s1, s2 = f_sb[n, 0] - c[b, 0], f_sb[n, 1] - c[b, 1], f_sb[n, 2] - c[b, 2]
            rb0 = R[b, 0, 0] * s0 + R[b, 0, 1] * s1 + R[b, 0, 2] * s2
            rb1 = R[b, 1, 0] * s0 + R[b, 1, 1] * s1 + R[b, 1, 2] * s2
            rb2 = R[b, 2, 0] * s0 + R[b, 2, 1] * s1 + R[b, 2, 2] * s2
            pb0, pb1, pb2 = x[b, 0] + rb0, x[b, 1] + rb1, x[b, 2] + rb2
        d0, d1, d2 = pa0 - pb0, pa1 - pb1, pa2 - pb2
        dn = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        # the law (_tension), before the fibre's scale
        length, l0n, law = dn + f_extra[n], l0[n], f_law[n]
        if law == LAW_SOFTPLUS:
            eps = (length / l0n - 1.0) * 100.0
            if eps <= 0.0:
                continue
            z = (eps + f_par[n, 1]) / f_par[n, 3]
            e = np.exp(-abs(z))
            F = f_par[n, 0] * (max(z, 0.0) + np.log1p(e)) + f_par[n, 2]
            dF = f_par[n, 0] / f_par[n, 3] * (1.0 / (1.0 + e) if z >= 0.0 else e / (1.0 + e))
            if not F > 0.0:
                F, dF = 0.0, 0.0
            if width <= 0.0:
                sm, dsm = 1.0, 0.0
            else:
                t = min(eps / width, 1.0)
                sm = t * t * (3.0 - 2.0 * t)
                dsm = 6.0 * t * (1.0 - t) / width if eps < width else 0.0
            T, dT = sm * F, (dsm * F + sm * dF) * 100.0 / l0n
        elif law == LAW_RUPP:
            dl = length - l0n
            if dl > 0.0 and dl < f_par[n, 0]:
                T, dT = f_par[n, 3] * dl ** f_par[n, 2], f_par[n, 2] * f_par[n, 3] * dl ** (f_par[n, 2] - 1.0)
            elif dl >= f_par[n, 0]:
                T, dT = f_par[n, 1] + f_par[n, 4] * (dl - f_par[n, 0]), f_par[n, 4]
            else:
                continue
        else:
            T, dT = f_par[n, 0], 0.0
        T = T * f_scale[n] * fm[n]
        dT = dT * f_scale[n] * fm[n]
        if T == 0.0 and dT == 0.0:
            continue
        inv = 1.0 / dn
        u0, u1, u2 = d0 * inv, d1 * inv, d2 * inv
        f0, f1, f2 = -T * u0, -T * u1, -T * u2
        if a >= 0:
            Q[a, 0] += f0
            Q[a, 1] += f1
            Q[a, 2] += f2
            Q[a, 3] += ra1 * f2 - ra2 * f1
            Q[a, 4] += ra2 * f0 - ra0 * f2
            Q[a, 5] += ra0 * f1 - ra1 * f0
        if b >= 0:
            Q[b, 0] -= f0
            Q[b, 1] -= f1
            Q[b, 2] -= f2
            Q[b, 3] -= rb1 * f2 - rb2 * f1
            Q[b, 4] -= rb2 * f0 - rb0 * f2
            Q[b, 5] -= rb0 * f1 - rb1 * f0
        if not jac:
            continue
        alpha = -T * inv
        beta = T * inv - dT
        if a >= 0:
            _acc_end(acc, a, beta, alpha, u0, u1, u2, ra0, ra1, ra2, 1.0, f0, f1, f2)
        if b >= 0:
            _acc_end(acc, b, beta, alpha, u0, u1, u2, rb0, rb1, rb2, -1.0, f0, f1, f2)
        if a >= 0 and b >= 0:
            ut, ft = (u0, u1, u2), (f0, f1, f2)
            rat, rbt = (ra0, ra1, ra2), (rb0, rb1, rb2)
            _fibre_block(J, a, b, -1.0, beta, alpha, ut, rat, rbt, 0.0, ft)
            _fibre_block(J, b, a, -1.0, beta, alpha, ut, rbt, rat, 0.0, ft)


@_inner
def _contacts(x, R, Q, J, jac, c, k_a, k_b, k_s, k_surf, k_stiff, ceps, s_orig, s_axes, s_coef, cm, w3, w33, acc):
    """Facet contact: the penalty on the gap of each contact point to the lower body's cubic surface. A point on a
    free body against a surface on the ground adds its Jacobian block to the body's accumulators (_acc_point, as the
    fibres); between two free bodies it goes to J directly (_assemble_j)."""
    ra, rb, f, v0, v1, v2 = w3[2], w3[3], w3[5], w3[7], w3[8], w3[9]
    K = w33[0]
    # screen: the surface coordinates (u, v, w) of a point are one affine map of its reference coordinates, G (S - c_a)
    # + t, built once per (surface, upper body, lower body); a point whose screened penetration is below -SCREEN_M
    # is open (round-off of the two formulas is ~1e-15 m), every other point is evaluated exactly as before
    g00 = g01 = g02 = g10 = g11 = g12 = g20 = g21 = g22 = t0 = t1 = t2 = 0.0
    key_s, key_a, key_b = -1, -2, -2
    for n in range(k_a.shape[0]):
        a, b = k_a[n], k_b[n]
        sid = k_surf[n]
        if sid != key_s or a != key_a or b != key_b:
            g00, g01, g02, g10, g11, g12, g20, g21, g22, t0, t1, t2 = _screen_map(x, R, c, a, b, s_orig[sid],
                                                                                 s_axes[sid])
            key_s, key_a, key_b = sid, a, b
        if a >= 0:
            s0, s1, s2 = k_s[n, 0] - c[a, 0], k_s[n, 1] - c[a, 1], k_s[n, 2] - c[a, 2]
        else:
            s0, s1, s2 = k_s[n, 0], k_s[n, 1], k_s[n, 2]
        us = g00 * s0 + g01 * s1 + g02 * s2 + t0
        vs = g10 * s0 + g11 * s1 + g12 * s2 + t1
        ws = g20 * s0 + g21 * s1 + g22 * s2 + t2
        if (ws - (s_coef[sid, 0] * (us * us * us) + s_coef[sid, 1] * (vs * vs * vs) + s_coef[sid, 2] * (us * us)
                  + s_coef[sid, 3] * (vs * vs) + s_coef[sid, 4])) > SCREEN_M:
            continue
        # scalars until the point is known to touch (array-writing helpers cost more than the arithmetic)
        p0, p1, p2, q0, q1, q2 = _point(x, R, c, a, k_s, n)
        e0, e1, e2, P0, P1, P2 = _in_body(x, R, c, b, p0, p1, p2)
        d0, d1, d2 = P0 - s_orig[sid, 0], P1 - s_orig[sid, 1], P2 - s_orig[sid, 2]
        u = d0 * s_axes[sid, 0, 0] + d1 * s_axes[sid, 0, 1] + d2 * s_axes[sid, 0, 2]
        v = d0 * s_axes[sid, 1, 0] + d1 * s_axes[sid, 1, 1] + d2 * s_axes[sid, 1, 2]
        w = d0 * s_axes[sid, 2, 0] + d1 * s_axes[sid, 2, 1] + d2 * s_axes[sid, 2, 2]
        u2, v2_ = u * u, v * v
        delta = -(w - (s_coef[sid, 0] * (u2 * u) + s_coef[sid, 1] * (v2_ * v) + s_coef[sid, 2] * u2
                       + s_coef[sid, 3] * v2_ + s_coef[sid, 4]))
        k = k_stiff[n]
        if delta > 0.0 and delta < ceps:
            Fm, dFm = k * (delta * delta) / (2 * ceps), k * delta / ceps
        elif delta >= ceps:
            Fm, dFm = k * (delta - ceps / 2), k
        else:
            continue
        Fm = Fm * cm[n]
        dFm = dFm * cm[n]
        if Fm == 0.0 and dFm == 0.0:
            continue
        cf0, cf1, cf2, cf3 = s_coef[sid, 0], s_coef[sid, 1], s_coef[sid, 2], s_coef[sid, 3]
        fu = 3 * cf0 * u2 + 2 * cf2 * u
        fv = 3 * cf1 * v2_ + 2 * cf3 * v
        # the surface normal (not unit) nm = -fu e_u - fv e_v + e_w in the lower body, v0 = R_b nm in the world
        nm0 = -fu * s_axes[sid, 0, 0] - fv * s_axes[sid, 1, 0] + s_axes[sid, 2, 0]
        nm1 = -fu * s_axes[sid, 0, 1] - fv * s_axes[sid, 1, 1] + s_axes[sid, 2, 1]
        nm2 = -fu * s_axes[sid, 0, 2] - fv * s_axes[sid, 1, 2] + s_axes[sid, 2, 2]
        v00, v01, v02 = _rot3(R, b, nm0, nm1, nm2)
        f0, f1, f2 = Fm * v00, Fm * v01, Fm * v02
        # the force on a (lever q about a) and -f on b (lever e about b), as _add_force
        if a >= 0:
            Q[a, 0] += f0
            Q[a, 1] += f1
            Q[a, 2] += f2
            Q[a, 3] += q1 * f2 - q2 * f1
            Q[a, 4] += q2 * f0 - q0 * f2
            Q[a, 5] += q0 * f1 - q1 * f0
        if b >= 0:
            Q[b, 0] += -1.0 * f0
            Q[b, 1] += -1.0 * f1
            Q[b, 2] += -1.0 * f2
            Q[b, 3] += -1.0 * (e1 * f2 - e2 * f1)
            Q[b, 4] += -1.0 * (e2 * f0 - e0 * f2)
            Q[b, 5] += -1.0 * (e0 * f1 - e1 * f0)
        if not jac:
            continue
        fuu = 6 * cf0 * u + 2 * cf2
        fvv = 6 * cf1 * v + 2 * cf3
        w0, w1, w2 = -dFm, -Fm * fuu, -Fm * fvv
        if b < 0 and a >= 0:
            _acc_point(acc, a, w0, w1, w2, v00, v01, v02, s_axes[sid, 0, 0], s_axes[sid, 0, 1], s_axes[sid, 0, 2],
                       s_axes[sid, 1, 0], s_axes[sid, 1, 1], s_axes[sid, 1, 2], q0, q1, q2, f0, f1, f2)
            continue
        ax = s_axes[sid]
        v0[0], v0[1], v0[2] = v00, v01, v02
        _rot(R, b, ax[0], v1)
        _rot(R, b, ax[1], v2)
        for i in range(3):
            for j in range(3):
                K[i, j] = w0 * v0[i] * v0[j] + w1 * v1[i] * v1[j] + w2 * v2[i] * v2[j]
        ra[0], ra[1], ra[2], rb[0], rb[1], rb[2] = q0, q1, q2, e0, e1, e2
        f[0], f[1], f[2] = f0, f1, f2
        _assemble_j(J, a, b, f, ra, rb, K, True)


@_inner
def _discs(x, R, Q, J, jac, c, d_up, d_lo, d_centre, d_frame, d_k, d_torque, kt, off, w3, w33):
    """Discs: the translational spring in the disc frame (row n of d_k: k_quadratic, k_linear, k_shear, lateral
    k_shear, torque-law code) and the torque law (Eq. 3 or cubic_deg) per project axis."""
    pa, ra, rb, P, f, v0, v1, v2 = w3[0], w3[2], w3[3], w3[4], w3[5], w3[7], w3[8], w3[9]
    K = w33[0]
    Ra, RB, Rrel, M, Ji = w33[1], w33[2], w33[3], w33[4], w33[5]
    phi, ph, Tq, dTq, tau, q4 = w3[10], w3[11], w3[12], w3[13], w3[14], w3[15]
    for n in range(d_up.shape[0]):
        a, b = d_up[n], d_lo[n]
        _relative_point(x, R, c, a, b, d_centre, n, pa, ra, rb, P)
        fr = d_frame[n]
        kq, kl, ks, ksl = d_k[n, 0], d_k[n, 1], d_k[n, 2], d_k[n, 3]
        cubic = d_k[n, 4] == DISC_LAW_CUBIC_DEG
        r0, r1, r2 = _frame_coords(P, d_centre[n], fr)
        cc = -r2
        if cc > 0.0:
            Fz, dFz = kq * (cc * cc) + kl * cc, -(2.0 * kq * cc + kl)
        else:
            Fz, dFz = -kt[n] * r2, -kt[n]
        _rot(R, b, fr[0], v0)
        _rot(R, b, fr[1], v1)
        _rot(R, b, fr[2], v2)
        F0, F1 = -ks * r0, -ksl * r1
        for i in range(3):
            f[i] = F0 * v0[i] + F1 * v1[i] + Fz * v2[i]
            for j in range(3):
                K[i, j] = -ks * v0[i] * v0[j] - ksl * v1[i] * v1[j] + dFz * v2[i] * v2[j]
        _assemble(Q, J, jac, a, b, f, ra, rb, K, True)
        for i in range(3):
            for j in range(3):
                Ra[i, j] = R[a, i, j] if a >= 0 else (1.0 if i == j else 0.0)
                RB[i, j] = R[b, i, j] if b >= 0 else (1.0 if i == j else 0.0)
        for i in range(3):
            for j in range(3):
                Rrel[i, j] = RB[0, i] * Ra[0, j] + RB[1, i] * Ra[1, j] + RB[2, i] * Ra[2, j]
        rotation_log(Rrel, phi, q4)
        for i in range(3):
            ph[i] = phi[i] - off[i]
        tor = d_torque[n]
        Tq[0], dTq[0] = _torque(ph[0], tor[0], cubic)
        if ph[1] >= 0.0:
            Tq[1], dTq[1] = _torque(ph[1], tor[1], cubic)
        else:
            Tq[1], dTq[1] = _torque(ph[1], tor[2], cubic)
        Tq[2], dTq[2] = _torque(ph[2], tor[3], cubic)
        for i in range(3):
            tau[i] = RB[i, 0] * Tq[0] + RB[i, 1] * Tq[1] + RB[i, 2] * Tq[2]
            if a >= 0:
                Q[a, 3 + i] -= tau[i]
            if b >= 0:
                Q[b, 3 + i] += tau[i]
        if not jac:
            continue
        _jl_inv(phi, Ji, w33[6])
        for i in range(3):          # Rrel <- diag(dT) Jinv RB^T
            for j in range(3):
                Rrel[i, j] = dTq[i] * (Ji[i, 0] * RB[j, 0] + Ji[i, 1] * RB[j, 1] + Ji[i, 2] * RB[j, 2])
        for i in range(3):
            for j in range(3):
                M[i, j] = RB[i, 0] * Rrel[0, j] + RB[i, 1] * Rrel[1, j] + RB[i, 2] * Rrel[2, j]
        for i in range(3):
            for j in range(3):
                if a >= 0:
                    J[a, 3 + i, a, 3 + j] -= M[i, j]
                if a >= 0 and b >= 0:
                    J[a, 3 + i, b, 3 + j] += M[i, j]
                    J[b, 3 + i, a, 3 + j] += M[i, j]
                if b >= 0:
                    J[b, 3 + i, b, 3 + j] -= M[i, j]
        if b >= 0:
            _add_hat(J, b, b, tau, -1.0, 3, 3)
            if a >= 0:
                _add_hat(J, a, b, tau, 1.0, 3, 3)


@_inline
def eval_one(x, R, Q, J, jac, md, fm, cm, l0, kt, off, w3, w33, acc):
    """Residual Q (nb, 6) (pre-filled with the loads) and Jacobian J (nb, 6, nb, 6) (zeroed) of one scenario;
    w3 (16, 4), w33 (8, 3, 3) and acc (nb, ACC) are work space."""
    (c, f_a, f_b, f_sa, f_sb, f_extra, f_law, f_par, f_scale, width,
     k_a, k_b, k_s, k_surf, k_stiff, ceps, s_orig, s_axes, s_coef,
     d_up, d_lo, d_centre, d_frame, d_k, d_torque) = md
    if jac:
        for k in range(acc.shape[0]):
            for i in range(ACC):
                acc[k, i] = 0.0
    _fibres(x, R, Q, J, jac, c, f_a, f_b, f_sa, f_sb, f_extra, f_law, f_par, f_scale, width, fm, l0, acc)
    _contacts(x, R, Q, J, jac, c, k_a, k_b, k_s, k_surf, k_stiff, ceps, s_orig, s_axes, s_coef, cm, w3, w33, acc)
    if jac:
        for k in range(acc.shape[0]):
            _acc_to_j(J, acc, k)
    _discs(x, R, Q, J, jac, c, d_up, d_lo, d_centre, d_frame, d_k, d_torque, kt, off, w3, w33)


@_inner
def copy_array(dst, src):
    """dst[...] = src for C-contiguous arrays of the same size, as one flat loop (numba's slice assignment of an array
    compiles a broadcasting path with its error handling at every use)."""
    d, s = dst.reshape(dst.size), src.reshape(src.size)
    for i in range(d.size):
        d[i] = s[i]


@_inner
def zero_array(a):
    """a[...] = 0 for a C-contiguous array (one flat loop, see :func:`copy_array`)."""
    f = a.reshape(a.size)
    for i in range(f.size):
        f[i] = 0.0


@_inner
def copy2(dst, src):
    """dst[...] = src for 2-d arrays of the same shape (loops over the indices: no reshape, which numba does through
    a C call, in the Newton iteration's per-trial copies)."""
    for i in range(dst.shape[0]):
        for j in range(dst.shape[1]):
            dst[i, j] = src[i, j]


@_inner
def copy3(dst, src):
    """dst[...] = src for 3-d arrays of the same shape (see :func:`copy2`)."""
    for i in range(dst.shape[0]):
        for j in range(dst.shape[1]):
            for k in range(dst.shape[2]):
                dst[i, j, k] = src[i, j, k]


@_inner
def zero4(a):
    """a[...] = 0 for a 4-d array (a Jacobian; see :func:`copy2`)."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            for k in range(a.shape[2]):
                for m in range(a.shape[3]):
                    a[i, j, k, m] = 0.0


@_inner
def same_array(a, b):
    """a == b element by element (C-contiguous arrays of the same size)."""
    fa, fb = a.reshape(a.size), b.reshape(b.size)
    for i in range(fa.size):
        if fa[i] != fb[i]:
            return False
    return True


@_inner
def same_row(a, s, s0):
    """Rows s and s0 of a per-scenario array (one shared row when a has a single row) are equal."""
    return a.shape[0] == 1 or same_array(a[s], a[s0])


@_jit
def evaluate_batch(x, R, L, fm, cm, l0, kt, off, jac, md, Q, J):
    """Q (B, nb, 6) and, with ``jac``, J (B, nb, 6, nb, 6) (both written here) of a batch."""
    w3, w33, acc = np.empty((16, 4)), np.empty((8, 3, 3)), np.empty((x.shape[1], ACC))
    for s in range(x.shape[0]):
        copy_array(Q[s], L[s if L.shape[0] > 1 else 0])
        if jac:
            zero_array(J[s])
        eval_one(x[s], R[s], Q[s], J[s] if jac else J[0], jac, md, fm[s if fm.shape[0] > 1 else 0],
                  cm[s if cm.shape[0] > 1 else 0], l0[s if l0.shape[0] > 1 else 0],
                  kt[s if kt.shape[0] > 1 else 0], off[s if off.shape[0] > 1 else 0], w3, w33, acc)
