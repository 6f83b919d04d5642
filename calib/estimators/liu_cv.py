"""The Liu-type estimator with k and d chosen by cross-validation on the calibration data.

The family of calib.estimators.liu, b = (Hs^T Hs + k I)^-1 (Hs^T y + d b_OLS) on the
column-scaled H, with (k, d) not from a formula (Hoerl-Kennard-Baldwin k, the MSE-optimal
d of Eq. 14) but from the data: the calibration poses are split into ``folds`` contiguous
blocks (rows of one pose stay together: ``rows_per_pose`` rows each, 9 for three targets),
each block is predicted from the fit on the others, and the (k, d) with the least held-out
squared error over a grid wins (k log-spaced, d / k in [0, 1]: ridge to OLS). Ties go to the
larger d / k (closer to OLS) and then the smaller k: a bias is taken only when the held-out
error asks for it. The estimate is the Liu-type fit on all rows with the chosen (k, d).
"""

from __future__ import annotations

import numpy as np

from calib.estimators.linear import LinearEstimate, estimate_from_filter, prepare, scale_columns

K_GRID = np.geomspace(1e-8, 10.0, 28)
D_OVER_K_GRID = np.linspace(0.0, 1.0, 11)


def _folds(n_rows: int, rows_per_pose: int, folds: int) -> np.ndarray:
    """Fold label per row: contiguous blocks of whole poses."""
    if n_rows % rows_per_pose:
        raise ValueError(f"{n_rows} rows are not whole poses of {rows_per_pose} rows")
    n_poses = n_rows // rows_per_pose
    if not 2 <= folds <= n_poses:
        raise ValueError(f"folds must be in [2, {n_poses}] (the number of poses), got {folds}")
    pose_fold = (np.arange(n_poses) * folds) // n_poses
    return np.repeat(pose_fold, rows_per_pose)


def heldout_errors(
    h: np.ndarray,
    y: np.ndarray,
    labels: np.ndarray,
    k_grid: np.ndarray = K_GRID,
    ratio_grid: np.ndarray = D_OVER_K_GRID,
) -> np.ndarray:
    """Held-out sum of squared errors (len(k_grid), len(ratio_grid)) over the folds."""
    hs, _ = scale_columns(h)
    y = np.asarray(y, dtype=float)
    k = np.asarray(k_grid, dtype=float)[:, None, None]
    d = k * np.asarray(ratio_grid, dtype=float)[None, :, None]
    sse = np.zeros((len(k_grid), len(ratio_grid)))
    for f in np.unique(labels):
        train, test = labels != f, labels == f
        u, s, vt = np.linalg.svd(hs[train], full_matrices=False)
        if s[-1] <= 1e-12 * s[0]:
            raise ValueError(f"fold {int(f)}: the other folds leave H rank deficient")
        alpha = (y[train] @ u) / s  # (m,)
        lam = s**2
        filt = (lam[None, None, :] + d) / (lam[None, None, :] + k)  # (K, D, m)
        b = (filt * alpha) @ vt  # (K, D, m) scaled units
        pred = b @ hs[test].T  # (K, D, n_test)
        sse += np.sum((pred - y[test]) ** 2, axis=-1)
    return sse


class LiuCV:
    name = "liu_cv"

    def __init__(self, folds: int = 7, rows_per_pose: int = 9) -> None:
        if int(folds) < 2:
            raise ValueError(f"liu_cv needs at least 2 folds, got {folds!r}")
        if int(rows_per_pose) < 1:
            raise ValueError(f"rows_per_pose must be >= 1, got {rows_per_pose!r}")
        self.folds = int(folds)
        self.rows_per_pose = int(rows_per_pose)

    def choose(self, h: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
        """(k, d, held-out RMS per row) with the least held-out error on the grid."""
        labels = _folds(len(y), self.rows_per_pose, self.folds)
        sse = heldout_errors(h, y, labels)
        # relative snapping, so that ties do not depend on the last bits of the BLAS
        best = float(np.min(sse))
        near = np.argwhere(sse <= best * (1.0 + 1e-9))
        # ties: the largest d / k (closest to OLS), then the smallest k
        i, j = min(near, key=lambda ij: (-ij[1], ij[0]))
        k = float(K_GRID[i])
        return k, k * float(D_OVER_K_GRID[j]), float(np.sqrt(sse[i, j] / len(y)))

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        y = np.asarray(y, dtype=float)
        k, d, rms = self.choose(h, y)
        s2 = float(prob.ols_rss(y) / (prob.n - prob.m)) if sigma2 is None else float(sigma2)
        f = (prob.lambdas + d) / (prob.lambdas + k)
        notes = (
            f"k = {k:.3g}, d = {d:.3g} (d / k = {d / k:.2f}) by {self.folds}-fold "
            f"cross-validation over poses; held-out RMS {rms * 1e3:.4g} mm per coordinate",
        )
        return estimate_from_filter(self.name, prob, y, f, s2, d, notes, k)

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Estimates (runs, m): (k, d) chosen again for every run."""
        return np.array([self.fit(h, y).x for y in np.atleast_2d(ys)])
