"""Intervertebral disc as a 6-DOF spring (paper 1, Eqs. 1-3).

Rotation: Eq. 3, ``T(phi) = p1 * tanh(phi**3 / p2) + p3 * phi`` per anatomical axis
(phi in rad, T in N*m, p2 in rad^3), flexion and extension with separate parameters.
Translation: axial compression ``F = k2 * c**2 + k1 * c`` (c = compression in m, F in N),
linear shear, and an optional tensile stiffness (0 by default: the paper's disc
transmits no traction).
"""
from __future__ import annotations

import numpy as np

# axis order of the project frame: x anterior (lateral bending), y left (flexion/extension), z superior (axial)
AXIS_DIRECTIONS = ("lateral_bending", "flexion", "axial_rotation")
#: torque laws of a 6-DOF spring: ``eq3`` (paper 1, Eq. 3, angle in rad) and ``cubic_deg``, the polynomial
#: ``T = (p1 |d|^2 + p2 |d| + p3) d`` with d the angle in degrees and T in N*m (the nonlinear rotational terms of
#: paper 2's intervertebral springs, lumbar.muscles.springs)
TORQUE_LAWS = ("eq3", "cubic_deg")
_DEG = 180.0 / np.pi


def torque_angle(phi, p1, p2, p3):
    """Eq. 3 torque [N*m] and its derivative [N*m/rad] at angle ``phi`` [rad]."""
    phi = np.asarray(phi, dtype=float)
    z = phi**3 / p2
    t = np.tanh(z)
    T = p1 * t + p3 * phi
    dT = p1 * (1.0 - t**2) * 3.0 * phi**2 / p2 + p3
    return T, dT


def torque_cubic_deg(phi, p1, p2, p3):
    """The ``cubic_deg`` torque [N*m] and its derivative [N*m/rad] at angle ``phi`` [rad]: odd in ``phi``, monotone
    where ``3 p1 d^2 + 2 p2 d + p3 > 0``."""
    phi = np.asarray(phi, dtype=float)
    d = np.abs(phi) * _DEG
    T = (p1 * d * d + p2 * d + p3) * phi * _DEG
    dT = (3.0 * p1 * d * d + 2.0 * p2 * d + p3) * _DEG
    return T, dT


def disc_torque(phi, torque_params, law="eq3"):
    """Restoring torque components of the disc for relative rotation vector ``phi`` (..., 3).

    ``torque_params`` maps 'flexion', 'extension', 'lateral_bending', 'axial_rotation' to
    (p1, p2, p3). Returns (T (..., 3), dT/dphi diagonal (..., 3)); T is the torque the disc
    exerts *against* the rotation magnitude, i.e. positive T opposes positive phi.
    Flexion is +phi_y, extension -phi_y; lateral bending and axial rotation are symmetric.
    """
    if law not in TORQUE_LAWS:
        raise ValueError(f"unknown disc torque law {law!r}; expected one of {TORQUE_LAWS}")
    f = torque_angle if law == "eq3" else torque_cubic_deg
    phi = np.asarray(phi, dtype=float)
    T = np.empty_like(phi)
    D = np.empty_like(phi)
    T[..., 0], D[..., 0] = f(phi[..., 0], *torque_params["lateral_bending"])
    Tf, Df = f(phi[..., 1], *torque_params["flexion"])
    Te, De = f(phi[..., 1], *torque_params["extension"])
    flex = phi[..., 1] >= 0.0
    T[..., 1] = np.where(flex, Tf, Te)
    D[..., 1] = np.where(flex, Df, De)
    T[..., 2], D[..., 2] = f(phi[..., 2], *torque_params["axial_rotation"])
    return T, D


def disc_axial_force(r_z, k_quadratic, k_linear, k_tension=0.0):
    """Axial disc force [N] on the upper vertebra (positive = pushes it superiorly).

    ``r_z`` [m] is the axial displacement of the upper disc centre relative to its reference
    (negative = compression). Compression c = -r_z gives ``k_quadratic*c**2 + k_linear*c``;
    tension (r_z > 0) gives ``-k_tension * r_z`` (no traction by default).
    Returns (force, d force / d r_z).
    """
    r_z = np.asarray(r_z, dtype=float)
    c = -r_z
    comp = c > 0.0
    F = np.where(comp, k_quadratic * c**2 + k_linear * c, -k_tension * r_z)
    dF = np.where(comp, -(2.0 * k_quadratic * c + k_linear), -k_tension)
    return F, dF
