"""Least-squares rigid transform between point sets (Kabsch/Horn, batched).

The fit finds ``R`` (proper rotation) and ``p`` minimising
``sum_i w_i |points_measured_i - (R @ points_local_i + p)|^2``. The local points
are shared; the measured points may carry leading batch axes (one fit per batch
element), which is how a tracked end-effector pose is recovered from target
readings at many machine configurations.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

COLLINEAR_RTOL = 1e-6
"""Default relative threshold on the second singular value of the centred local points."""


class RigidFitError(ValueError):
    """Raised when a rigid transform cannot be fitted from the given points."""


def _as_points(x: ArrayLike, name: str) -> Array:
    arr = np.asarray(x, dtype=float)
    if arr.ndim < 2 or arr.shape[-1] != 3:
        raise RigidFitError(f"{name} must have shape (..., N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise RigidFitError(f"{name} contains non-finite values (NaN or inf)")
    return arr


def _as_weights(weights: ArrayLike | None, n: int, batch: tuple[int, ...]) -> Array:
    if weights is None:
        return np.full(n, 1.0 / n)
    w = np.asarray(weights, dtype=float)
    if w.ndim < 1 or w.shape[-1] != n:
        raise RigidFitError(f"weights must have shape (..., {n}) to match N={n}, got {w.shape}")
    try:
        ok = np.broadcast_shapes(w.shape[:-1], batch) == batch
    except ValueError:
        ok = False
    if not ok:
        raise RigidFitError(
            f"weights batch shape {w.shape[:-1]} does not broadcast to the measurement "
            f"batch shape {batch}"
        )
    if not np.all(np.isfinite(w)):
        raise RigidFitError("weights contain non-finite values (NaN or inf)")
    if np.any(w < 0):
        raise RigidFitError("weights must be non-negative")
    if np.any(np.count_nonzero(w > 0, axis=-1) < 3):
        raise RigidFitError("need at least 3 points with positive weight")
    return w / np.sum(w, axis=-1, keepdims=True)


def fit_rigid_transform(
    points_local: ArrayLike,
    points_measured: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    collinear_rtol: float = COLLINEAR_RTOL,
) -> tuple[Array, Array]:
    """Fit ``points_measured ≈ R @ points_local + p`` in the weighted least-squares sense.

    Args:
        points_local: (N, 3) points in the body frame, shared by all batch elements.
        points_measured: (..., N, 3) measured points in the reference frame.
        weights: optional non-negative weights, shape (N,) or (..., N); ``None`` = equal.
        collinear_rtol: the (weighted, centred) local points are rejected as collinear
            when their second singular value is at most this fraction of the first.

    Returns:
        ``R`` (..., 3, 3) with ``det(R) = +1`` and ``p`` (..., 3).

    Raises:
        RigidFitError: N < 3, mismatched shapes, non-finite input, invalid weights,
            or (nearly) collinear local points.
    """
    local = _as_points(points_local, "points_local")
    if local.ndim != 2:
        raise RigidFitError(f"points_local must have shape (N, 3), got {local.shape}")
    n = local.shape[0]
    if n < 3:
        raise RigidFitError(f"need at least 3 points to fit a rigid transform, got N={n}")
    meas = _as_points(points_measured, "points_measured")
    if meas.shape[-2] != n:
        raise RigidFitError(
            f"points_measured has {meas.shape[-2]} points per set but points_local has {n} "
            f"(shapes {meas.shape} vs {local.shape})"
        )
    batch = meas.shape[:-2]
    w = _as_weights(weights, n, batch)

    c_local = np.einsum("...n,nk->...k", w, local)
    c_meas = np.einsum("...n,...nk->...k", w, meas)
    a = local - c_local[..., None, :]
    b = meas - c_meas[..., None, :]

    sv = np.linalg.svd(np.sqrt(w)[..., None] * a, compute_uv=False)
    degenerate = sv[..., 1] <= collinear_rtol * sv[..., 0]
    if np.any(degenerate):
        ratio = float(np.min(sv[..., 1] / np.where(sv[..., 0] > 0, sv[..., 0], 1.0)))
        raise RigidFitError(
            "points_local are (nearly) collinear or coincident: second singular value of the "
            f"centred points is {ratio:.3g} times the first (threshold {collinear_rtol:g}); "
            "the rotation about their line is undetermined"
        )

    h = np.einsum("...n,...ni,...nj->...ij", w, a, b)
    u, _, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, -1, -2)
    ut = np.swapaxes(u, -1, -2)
    d = np.sign(np.linalg.det(v @ ut))
    v = v.copy()
    v[..., :, 2] *= d[..., None]
    rot = v @ ut
    p = c_meas - np.einsum("...ij,...j->...i", rot, c_local)
    return rot, p


def fit_residuals(
    points_local: ArrayLike, points_measured: ArrayLike, R: ArrayLike, p: ArrayLike
) -> Array:
    """Residuals ``points_measured - (R @ points_local + p)``, shape (..., N, 3)."""
    local = np.asarray(points_local, dtype=float)
    meas = np.asarray(points_measured, dtype=float)
    rot = np.asarray(R, dtype=float)
    trans = np.asarray(p, dtype=float)
    if local.ndim != 2 or local.shape[1] != 3:
        raise RigidFitError(f"points_local must have shape (N, 3), got {local.shape}")
    if meas.ndim < 2 or meas.shape[-2:] != local.shape:
        raise RigidFitError(
            f"points_measured must have shape (..., {local.shape[0]}, 3), got {meas.shape}"
        )
    if rot.shape[-2:] != (3, 3) or trans.shape[-1:] != (3,):
        raise RigidFitError(f"R must be (..., 3, 3) and p (..., 3), got {rot.shape}, {trans.shape}")
    predicted = np.einsum("...ij,nj->...ni", rot, local) + trans[..., None, :]
    return meas - predicted
