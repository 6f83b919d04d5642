"""Shared pieces of the linear estimators of dp = H dchi + eps.

All estimators work on the column-scaled H (unit column norms), so that millimetres and
radians do not mix; estimates and covariances are mapped back to the original units.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from calib.identifiability import RANK_RTOL


@dataclass(frozen=True)
class LinearEstimate:
    method: str
    x: np.ndarray  # (m,) original units
    covariance: np.ndarray  # (m, m) sampling covariance A cov(y) A^T, original units
    std_errors: np.ndarray  # sqrt(diag(covariance))
    sigma2: float  # noise variance used
    bias_parameter: float | None = None  # Liu d, ridge k, PCR component count
    notes: tuple[str, ...] = ()
    scale_parameter: float | None = None  # Liu's k (the paper's Eq. 11 has k = 1)


class Estimator(Protocol):
    name: str

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate: ...

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Scaled:
    """The scaled problem: hs = h / scale, its SVD, and the OLS solution in scaled units."""

    hs: np.ndarray
    scale: np.ndarray
    u: np.ndarray
    s: np.ndarray
    vt: np.ndarray

    @property
    def n(self) -> int:
        return self.hs.shape[0]

    @property
    def m(self) -> int:
        return self.hs.shape[1]

    def ols(self, y: np.ndarray) -> np.ndarray:
        """OLS in scaled units for y (n,) or (runs, n) -> (m,) or (runs, m)."""
        return ((y @ self.u) / self.s) @ self.vt

    def rss(self, y: np.ndarray, b: np.ndarray) -> np.ndarray:
        r = y - b @ self.hs.T
        return np.sum(r * r, axis=-1)

    def unscale_cov(self, cov_s: np.ndarray) -> np.ndarray:
        return cov_s / np.outer(self.scale, self.scale)


def prepare(h: np.ndarray, y: np.ndarray | None = None) -> Scaled:
    """Validate and scale; errors name the cause."""
    h = np.asarray(h, dtype=float)
    if h.ndim != 2:
        raise ValueError(f"H must be a matrix, got shape {h.shape}")
    n, m = h.shape
    if not np.all(np.isfinite(h)):
        raise ValueError("H contains NaN or inf")
    if y is not None:
        y = np.asarray(y, dtype=float)
        if y.shape[-1] != n:
            raise ValueError(f"y has {y.shape[-1]} entries per draw but H has {n} rows")
        if not np.all(np.isfinite(y)):
            raise ValueError("the measurements y contain NaN or inf")
    if n <= m:
        raise ValueError(f"{n} equations for {m} unknowns: a linear estimator needs more")
    scale = np.linalg.norm(h, axis=0)
    if np.any(scale == 0):
        raise ValueError(f"column(s) {np.flatnonzero(scale == 0).tolist()} of H are zero")
    hs = h / scale
    u, s, vt = np.linalg.svd(hs, full_matrices=False)
    if s[-1] <= RANK_RTOL * s[0]:
        raise ValueError(
            f"H is rank deficient (rank {int(np.sum(s > RANK_RTOL * s[0]))} of {m}): reconstruct "
            "an identifiable set first (calib.reconstruction)"
        )
    return Scaled(hs, scale, u, s, vt)


def residual_variance(prob: Scaled, y: np.ndarray, b_ols: np.ndarray) -> float:
    """Unbiased noise variance RSS / (n - m) from the OLS fit."""
    return float(prob.rss(y, b_ols) / (prob.n - prob.m))


def estimate_from_map(
    method: str,
    prob: Scaled,
    a_s: np.ndarray,
    y: np.ndarray,
    sigma2: float,
    bias: float | None,
    notes: tuple[str, ...] = (),
    scale: float | None = None,
) -> LinearEstimate:
    """Package a linear estimator b_s = a_s y (scaled units) in original units."""
    b_s = a_s @ y
    cov = prob.unscale_cov(sigma2 * (a_s @ a_s.T))
    x = b_s / prob.scale
    return LinearEstimate(
        method, x, cov, np.sqrt(np.clip(np.diag(cov), 0, None)), sigma2, bias, notes, scale
    )
