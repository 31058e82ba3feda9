"""Batched SO(3) helpers (rotation vectors, Rodrigues, inverse left Jacobian).

All functions accept leading batch dimensions. Rotation vectors are in rad.
Convention: a spatial (left) increment ``w`` updates ``R <- exp(w) @ R``.
"""
from __future__ import annotations

import sys

import numpy as np

_SMALL = 1e-8


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (broadcasting); faster than np.cross for small stacks."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def hat(v: np.ndarray) -> np.ndarray:
    """Skew matrix ``[v]x`` so that ``hat(v) @ u == cross(v, u)``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrices from rotation vectors (Rodrigues), batched."""
    w = np.asarray(w, dtype=float)
    flat = w.reshape(-1, 3)
    from scipy.spatial.transform import Rotation  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    mats = Rotation.from_rotvec(flat).as_matrix()
    return mats.reshape(w.shape[:-1] + (3, 3))


def log_reference(R: np.ndarray) -> np.ndarray:
    """Rotation vectors from rotation matrices, batched (angle in [0, pi]): scipy's ``Rotation`` (the reference of
    :func:`log`; it also orthogonalises a matrix that is not, and refuses a left-handed one)."""
    R = np.asarray(R, dtype=float)
    flat = R.reshape(-1, 3, 3)
    from scipy.spatial.transform import Rotation  # noqa: PLC0415
    vecs = Rotation.from_matrix(flat).as_rotvec()
    return vecs.reshape(R.shape[:-2] + (3,))


def log(R: np.ndarray) -> np.ndarray:
    """Rotation vectors from rotation matrices, batched (angle in [0, pi]).

    Where the compiled solver core is loaded and active (:mod:`lumbar.mechanics.kernel`, which this module does not
    import: numba stays out of processes that never solve), its ``log_batch``: the steps of :func:`log_reference`,
    bit for bit, without scipy's per-call overhead (about ten times the arithmetic for the few matrices of one model
    evaluation, measured in the calibration's metrics). Else, and for a matrix that is not orthogonal or not
    right-handed, :func:`log_reference`."""
    k = sys.modules.get("lumbar.mechanics.kernel")
    if k is not None and k.active():
        R = np.asarray(R, dtype=float)
        flat = np.ascontiguousarray(R.reshape(-1, 3, 3))
        out = np.empty((flat.shape[0], 3))
        if k.log_batch(flat, out):
            return out.reshape(R.shape[:-2] + (3,))
    return log_reference(R)


def left_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """Inverse left Jacobian of SO(3): d log(exp(w) R) / dw at w = 0, with phi = log(R).

    J^-1 = I - 1/2 [phi]x + (1/theta^2 - (1 + cos theta) / (2 theta sin theta)) [phi]x^2
    """
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1)
    K = hat(phi)
    K2 = K @ K
    small = theta < 1e-4
    th = np.where(small, 1.0, theta)
    coef = np.where(small, 1.0 / 12.0 + theta**2 / 720.0,
                    1.0 / th**2 - (1.0 + np.cos(th)) / (2.0 * th * np.sin(th)))
    eye = np.broadcast_to(np.eye(3), K.shape)
    return eye - 0.5 * K + coef[..., None, None] * K2


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    """Left Jacobian of SO(3): exp(phi + dphi) = exp(J_l(phi) dphi) exp(phi) to first order, batched.

    J_l = I + (1 - cos theta) / theta^2 [phi]x + (theta - sin theta) / theta^3 [phi]x^2
    """
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1)
    K = hat(phi)
    small = theta < 1e-4
    th = np.where(small, 1.0, theta)
    c1 = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    c2 = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (th - np.sin(th)) / th**3)
    eye = np.broadcast_to(np.eye(3), K.shape)
    return eye + c1[..., None, None] * K + c2[..., None, None] * (K @ K)
