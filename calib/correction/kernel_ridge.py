"""Kernel ridge regression (the mean of a Gaussian process) of the residual over pose features.

The correction is the smallest honest implementation in numpy/scipy (scikit-learn is no
dependency of the project, and its GaussianProcessRegressor would choose the length scale by
the marginal likelihood, not by held-out poses): an RBF kernel
``k(x, x') = s2 exp(-|z - z'|^2 / (2 l^2 d))`` over the features standardised by their mean
and standard deviation on the calibration poses (z, d of them), fitted to the residual
vectors (N, R). The mean is ``K* (C + r I)^-1 Y`` with C the kernel matrix at unit variance
and r the noise-to-signal variance ratio; its variance per output
``s2 (1 - k*^T (C + r I)^-1 k*)``, with s2 the maximum-likelihood signal variance of the
chosen (l, r) (closed form: ``tr(Y^T (C + r I)^-1 Y) / (m R)``).

At most ``MAX_TRAINING_POSES`` poses, evenly spaced through the calibration poses, carry the
correction (as the diagnosis's kernel smoother does): the memory is that many squared plus
``BLOCK`` times that many per evaluation, linear in the poses evaluated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from common.worker_processes import map_in_order, worker_count

MAX_TRAINING_POSES = 1500
# ... and at most this many in each cross-validation fold's fit, which only chooses the length
# scale and the ratio: 175 Cholesky factors of its kernel (5 folds x 7 length scales x 5
# ratios) cost n^3 / 3 each; every campaign of up to 1,250 poses (folds of 1,000) is
# cross-validated on all of them
CV_TRAINING_POSES = 1000
BLOCK = 512  # poses evaluated at once
# length scales, in units of the features' standard deviation (times sqrt of their count),
# and noise-to-signal variance ratios the cross-validation chooses from
LENGTH_SCALES = (0.1, 0.15, 0.25, 0.4, 0.6, 1.0, 1.6)
RATIOS = (1e-3, 1e-2, 0.1, 1.0, 10.0)


def training_subset(n: int, cap: int | None = None) -> np.ndarray:
    """All of ``n`` poses up to ``cap`` (default MAX_TRAINING_POSES), else ``cap`` of them
    evenly spaced (deterministic)."""
    cap = MAX_TRAINING_POSES if cap is None else cap
    if n <= cap:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, cap).round().astype(int))


def sq_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances (len(a), len(b)), summed coordinate by coordinate (no
    a.b^T product: the same digits whatever the BLAS)."""
    d2 = np.zeros((len(a), len(b)))
    work = np.empty_like(d2)  # each coordinate's squared differences, in place
    for j in range(a.shape[1]):
        np.subtract.outer(a[:, j], b[:, j], out=work)
        np.multiply(work, work, out=work)
        d2 += work
    return d2


def nearest(z: np.ndarray, z_train: np.ndarray) -> np.ndarray:
    """Distance of each row of ``z`` to its nearest row of ``z_train`` (in blocks)."""
    out = np.empty(len(z))
    for lo in range(0, len(z), BLOCK):
        out[lo : lo + BLOCK] = np.sqrt(np.min(sq_dist(z[lo : lo + BLOCK], z_train), axis=1))
    return out


@dataclass(frozen=True)
class KernelRidge:
    """A fitted correction: standardised training features, weights, kernel and scaling."""

    z_train: np.ndarray  # (m, d) standardised features of the poses that carry it
    weights: np.ndarray  # (m, R) (C + r I)^-1 Y
    length_scale: float  # l, in standardised units per sqrt(d)
    ratio: float  # r, noise-to-signal variance ratio
    signal_var: float  # s2, m^2
    mean: np.ndarray  # (d,) feature means
    scale: np.ndarray  # (d,) feature standard deviations

    def standardise(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, dtype=float) - self.mean) / self.scale

    def kernel(self, z: np.ndarray) -> np.ndarray:
        d = self.z_train.shape[1]
        return np.exp(-0.5 * sq_dist(z, self.z_train) / (self.length_scale**2 * d))

    def predict(self, x: np.ndarray, with_std: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Mean (N, R) and predictive standard deviation (N,) per output at features ``x``."""
        z = self.standardise(x)
        mean = np.empty((len(z), self.weights.shape[1]))
        std = np.zeros(len(z))
        chol = self._chol() if with_std else None
        for lo in range(0, len(z), BLOCK):
            k = self.kernel(z[lo : lo + BLOCK])
            mean[lo : lo + BLOCK] = k @ self.weights
            if chol is not None:
                v = cho_solve(chol, k.T)
                reduction = np.einsum("ij,ji->i", k, v)
                std[lo : lo + BLOCK] = np.sqrt(self.signal_var * np.clip(1 - reduction, 0, 1))
        return mean, std

    def loo_mean(self) -> np.ndarray:
        """The mean (m, R) at each training pose fitted without it (a Gaussian process's
        closed form: y_i - alpha_i / [(C + r I)^-1]_ii, with y = (C + r I) alpha)."""
        chol = self._chol()
        c = self.kernel(self.z_train) + self.ratio * np.eye(len(self.z_train))
        y = c @ self.weights
        inv_diag = np.diag(cho_solve(chol, np.eye(len(c))))
        return y - self.weights / inv_diag[:, None]

    def _chol(self):
        return ridge_factor(self.kernel(self.z_train), self.ratio)


def ridge_factor(c: np.ndarray, ratio: float):
    """The Cholesky factor of the kernel ``c`` plus ``ratio`` I: what the weights and the
    variances solve with, in the fit and in each cross-validation fold alike."""
    return cho_factor(c + ratio * np.eye(len(c)), lower=True)


def fit_kernel_ridge(
    x: np.ndarray, y: np.ndarray, length_scale: float, ratio: float, mean=None, scale=None
) -> KernelRidge:
    """The correction of ``y`` (n, R) over features ``x`` (n, d) at a given (l, r), on at
    most MAX_TRAINING_POSES evenly spaced poses; ``mean``/``scale`` the features' scaling
    (default: of ``x``)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if mean is None:
        mean, scale = standardisation(x)
    sub = training_subset(len(x))
    z = (x[sub] - mean) / scale
    d = z.shape[1]
    chol = ridge_factor(np.exp(-0.5 * sq_dist(z, z) / (length_scale**2 * d)), ratio)
    w = cho_solve(chol, y[sub])
    s2 = float(np.sum(y[sub] * w)) / max(w.size, 1)
    return KernelRidge(z, w, float(length_scale), float(ratio), s2, mean, scale)


def standardisation(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of each feature (a constant feature: scale 1)."""
    mean, scale = x.mean(axis=0), x.std(axis=0)
    return mean, np.where(scale > 0, scale, 1.0)


@dataclass(frozen=True)
class CrossValidation:
    """Held-out results of every (l, r) and of the chosen one, per pose."""

    sse: np.ndarray  # (len(LENGTH_SCALES), len(RATIOS)) held-out SSE over all folds
    length_scale: float
    ratio: float
    before: np.ndarray  # (n, R) the residual itself
    after: np.ndarray  # (n, R) held-out residual after the chosen correction
    distance: np.ndarray  # (n,) standardised distance to the nearest training pose of its fold


def cross_validate(
    x: np.ndarray,
    y: np.ndarray,
    labels: np.ndarray,
    length_scales: tuple[float, ...] = LENGTH_SCALES,
    ratios: tuple[float, ...] = RATIOS,
) -> CrossValidation:
    """K-fold cross-validation over poses (``labels``: the fold of each pose, e.g. blocks of
    the measurement order): each (l, r) fitted on the other folds and scored on the fold, with the
    arithmetic of :func:`fit_kernel_ridge` (a Cholesky factor of each training kernel plus r
    I, and the held-out kernel times the weights: poses x training poses x R; five of these
    took 0.08 s at 1,000 training and 1,800 held-out poses, where one eigendecomposition
    serving all five ratios and the held-out kernel in its eigenbasis, poses x training
    poses^2, took 0.22 s). The features' scaling is the whole set's (a scaling, not a fit
    of the residual)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    mean, scale = standardisation(x)
    z = (x - mean) / scale
    d = z.shape[1]
    n_l, n_r = len(length_scales), len(ratios)
    pred = np.zeros((n_l, n_r, *y.shape))
    distance = np.zeros(len(z))
    # per fold: its poses, its training poses' features and targets and their squared
    # distances (the held-out poses' distances, poses x training poses, are made by the
    # process that evaluates the fold, below)
    fold_data = []
    for f in np.unique(labels):
        test = labels == f
        tr_idx = np.flatnonzero(~test)[training_subset(int(np.sum(~test)), CV_TRAINING_POSES)]
        zt = z[tr_idx]
        # -0.5 d2 of the training poses: every length scale's kernel is exp(this / (l^2 d))
        fold_data.append((test, zt, y[tr_idx], np.multiply(sq_dist(zt, zt), -0.5)))
    tasks = [(k, i) for k in range(len(fold_data)) for i in range(n_l)]
    # d2 of one fold's held-out poses to its training poses, kept by the process that
    # evaluates its length scales (each worker its own: one fold's at a time in memory)
    held_d2: dict[int, np.ndarray] = {}

    def one(t: int) -> tuple[np.ndarray | None, np.ndarray]:
        """Predictions (n_r, poses, R) of a fold's poses at one length scale, and their
        distance to the nearest training pose when this process first made their d2."""
        k, i = tasks[t]
        test, zt, yt, half_tt = fold_data[k]
        nearest = None
        if k not in held_d2:
            held_d2.clear()
            held_d2[k] = sq_dist(z[test], zt)
            nearest = np.sqrt(np.min(held_d2[k], axis=1))
        scale = length_scales[i] ** 2 * d
        kv = np.multiply(held_d2[k], -0.5)  # exp(-0.5 d2 / (l^2 d))
        np.divide(kv, scale, out=kv)
        np.exp(kv, out=kv)
        c = np.exp(half_tt / scale)
        out = np.empty((n_r, len(kv), yt.shape[1]))
        for j, r in enumerate(ratios):  # the fit's own arithmetic: (C + r I)^-1 Y by Cholesky
            np.matmul(kv, cho_solve(ridge_factor(c, r), yt), out=out[j])
        return nearest, out

    # each (fold, length scale) its own factors: side by side in worker processes on a long
    # run, the numbers of one process bit for bit (common.worker_processes)
    workers = worker_count(y.size, len(tasks))
    for (k, i), (nearest, held) in zip(tasks, map_in_order(one, len(tasks), workers), strict=True):
        test = fold_data[k][0]
        pred[i][:, test] = held
        if nearest is not None:  # the same numbers from whichever process made them
            distance[test] = nearest
    held_d2.clear()
    sse = np.sum((y[None, None] - pred) ** 2, axis=(2, 3))
    i, j = np.unravel_index(int(np.argmin(sse)), sse.shape)
    return CrossValidation(sse, length_scales[i], ratios[j], y, y - pred[i, j], distance)
