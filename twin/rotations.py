"""Rotation conversions (pure numpy, batched over leading axes).

Conventions:
* rotation matrices act on column vectors, ``p_parent = R @ p_child``;
* quaternions are ``w, x, y, z`` (MuJoCo's order; pinocchio uses ``x, y, z, w``);
* ``rpy`` follows the second paper: ``R = Rz(gamma) @ Ry(beta) @ Rx(alpha)`` with
  ``rpy = (alpha, beta, gamma)`` about the fixed x, y, z axes.
Names read ``a_from_b``: ``matrix_from_rotvec`` turns a rotation vector into a matrix.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def skew(v: ArrayLike) -> Array:
    """Cross-product matrices ``[v]x`` for vectors of shape (..., 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def matrix_from_rotvec(rotvec: ArrayLike) -> Array:
    """Rodrigues' formula, with a series expansion near zero angle."""
    w = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    k = skew(w)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * k + b * (k @ k)


SMALL_BATCH = 8  # up to this many matrices, rotvec_from_matrix works on Python floats


def rotvec_from_matrix(matrix: ArrayLike) -> Array:
    """Inverse of :func:`matrix_from_rotvec` (angle in [0, pi]).

    A few matrices (a tool goal, a machine's closures: the Newton loops of the kinematics
    call this at every step) go through :func:`_rotvec_one`, the same arithmetic on Python
    floats in the same order, so the same numbers bit for bit without numpy's per-call
    overhead (tests/test_rotations.py compares both paths)."""
    r = np.asarray(matrix, dtype=float)
    if r.shape == (3, 3):
        out = _rotvec_one(r.tolist())
        if out is not None:
            return np.array(out)
    elif r.ndim == 3 and r.shape[1:] == (3, 3) and 0 < r.shape[0] <= SMALL_BATCH:
        rows = [_rotvec_one(m) for m in r.tolist()]
        if all(row is not None for row in rows):
            return np.array(rows)
    return _rotvec_from_matrix_array(r)


def _rotvec_one(m: list[list[float]]) -> list[float] | None:
    """:func:`quat_from_matrix` then :func:`_rotvec_from_matrix_array` for one matrix (nested
    lists), operation by operation; None for a matrix with NaN (left to the array path)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    diag = (m00 + m11 + m22, m00, m11, m22)
    if any(d != d for d in diag):
        return None
    best = 0
    for i in (1, 2, 3):  # np.argmax: the first largest
        if diag[i] > diag[best]:
            best = i
    if best == 0:
        q = [1 + m00 + m11 + m22, m21 - m12, m02 - m20, m10 - m01]
    elif best == 1:
        q = [m21 - m12, 1 + m00 - m11 - m22, m01 + m10, m02 + m20]
    elif best == 2:
        q = [m02 - m20, m01 + m10, 1 - m00 + m11 - m22, m12 + m21]
    else:
        q = [m10 - m01, m02 + m20, m12 + m21, 1 - m00 - m11 + m22]
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    q = [c / norm for c in q]
    if q[0] < 0:
        q = [-c for c in q]
    w = min(max(q[0], -1.0), 1.0)
    v = q[1:]
    sin_half = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if sin_half < 1e-12:
        scale = 2.0 / (1.0 if w == 0 else w)
    else:
        scale = float(2.0 * np.arctan2(sin_half, w)) / sin_half  # numpy's arctan2, as below
    return [c * scale for c in v]


def _rotvec_from_matrix_array(r: Array) -> Array:
    quat = quat_from_matrix(r)
    w = np.clip(quat[..., 0], -1.0, 1.0)
    v = quat[..., 1:]
    sin_half = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(sin_half, w)
    small = sin_half < 1e-12
    scale = np.where(small, 2.0 / np.where(w == 0, 1.0, w), angle / np.where(small, 1.0, sin_half))
    return v * scale[..., None]


def quat_from_matrix(matrix: ArrayLike) -> Array:
    """Unit quaternion (w, x, y, z) with w >= 0 from rotation matrices (..., 3, 3)."""
    r = np.asarray(matrix, dtype=float)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    cands = np.stack(
        [
            np.stack(
                [
                    1 + m00 + m11 + m22,
                    r[..., 2, 1] - r[..., 1, 2],
                    r[..., 0, 2] - r[..., 2, 0],
                    r[..., 1, 0] - r[..., 0, 1],
                ],
                axis=-1,
            ),
            np.stack(
                [
                    r[..., 2, 1] - r[..., 1, 2],
                    1 + m00 - m11 - m22,
                    r[..., 0, 1] + r[..., 1, 0],
                    r[..., 0, 2] + r[..., 2, 0],
                ],
                axis=-1,
            ),
            np.stack(
                [
                    r[..., 0, 2] - r[..., 2, 0],
                    r[..., 0, 1] + r[..., 1, 0],
                    1 - m00 + m11 - m22,
                    r[..., 1, 2] + r[..., 2, 1],
                ],
                axis=-1,
            ),
            np.stack(
                [
                    r[..., 1, 0] - r[..., 0, 1],
                    r[..., 0, 2] + r[..., 2, 0],
                    r[..., 1, 2] + r[..., 2, 1],
                    1 - m00 - m11 + m22,
                ],
                axis=-1,
            ),
        ],
        axis=-2,
    )
    diag = np.stack([m00 + m11 + m22, m00, m11, m22], axis=-1)
    best = np.argmax(diag, axis=-1)
    q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def matrix_from_quat(quat: ArrayLike) -> Array:
    """Rotation matrices from quaternions (w, x, y, z); the input is normalised."""
    q = np.asarray(quat, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty((*q.shape[:-1], 3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - z * w)
    out[..., 0, 2] = 2 * (x * z + y * w)
    out[..., 1, 0] = 2 * (x * y + z * w)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - x * w)
    out[..., 2, 0] = 2 * (x * z - y * w)
    out[..., 2, 1] = 2 * (y * z + x * w)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def quat_multiply(a: ArrayLike, b: ArrayLike) -> Array:
    """Hamilton product ``a * b`` of (w, x, y, z) quaternions."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    aw, av = a[..., :1], a[..., 1:]
    bw, bv = b[..., :1], b[..., 1:]
    w = aw * bw - np.sum(av * bv, axis=-1, keepdims=True)
    v = aw * bv + bw * av + np.cross(av, bv)
    return np.concatenate([w, v], axis=-1)


def quat_from_rotvec(rotvec: ArrayLike) -> Array:
    """Quaternion (w, x, y, z) of a rotation vector."""
    w = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(w, axis=-1, keepdims=True)
    small = angle < 1e-10
    safe = np.where(small, 1.0, angle)
    s = np.where(small, 0.5 - angle**2 / 48.0, np.sin(safe / 2) / safe)
    return np.concatenate([np.cos(angle / 2), w * s], axis=-1)


def matrix_from_rpy(rpy: ArrayLike) -> Array:
    """``Rz(gamma) @ Ry(beta) @ Rx(alpha)`` for ``rpy = (alpha, beta, gamma)`` (..., 3)."""
    a = np.asarray(rpy, dtype=float)
    ca, sa = np.cos(a[..., 0]), np.sin(a[..., 0])
    cb, sb = np.cos(a[..., 1]), np.sin(a[..., 1])
    cg, sg = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = np.empty((*a.shape[:-1], 3, 3))
    out[..., 0, 0] = cg * cb
    out[..., 0, 1] = cg * sb * sa - sg * ca
    out[..., 0, 2] = cg * sb * ca + sa * sg
    out[..., 1, 0] = sg * cb
    out[..., 1, 1] = sg * sb * sa + cg * ca
    out[..., 1, 2] = sg * sb * ca - cg * sa
    out[..., 2, 0] = -sb
    out[..., 2, 1] = cb * sa
    out[..., 2, 2] = cb * ca
    return out


def rpy_from_matrix(matrix: ArrayLike) -> Array:
    """Inverse of :func:`matrix_from_rpy` for ``|beta| < pi/2``."""
    r = np.asarray(matrix, dtype=float)
    beta = -np.arcsin(np.clip(r[..., 2, 0], -1.0, 1.0))
    alpha = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    gamma = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    return np.stack([alpha, beta, gamma], axis=-1)


def rotation_angle(matrix: ArrayLike) -> Array:
    """Angle of rotation matrices (..., 3, 3), robust near zero."""
    return np.linalg.norm(rotvec_from_matrix(matrix), axis=-1)
