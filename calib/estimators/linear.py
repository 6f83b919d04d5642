"""Shared pieces of the linear estimators of the linearised model dp = H dchi + eps.

All estimators work on the column-scaled Hs = H / scale (each column divided by its
Euclidean norm), so that millimetres and radians do not mix; estimates and covariances are
mapped back to the original units (x = b / scale for an estimate b of the scaled problem).

With the thin SVD Hs = U diag(s) V^T, the eigen-decomposition of Hs^T Hs is
Phi = V, lambda = s^2, and the OLS estimate in canonical coordinates is
alpha = Phi^T b_OLS = U^T y / s. OLS, Liu, ridge and PCR are all spectral filters:
b = Phi diag(f) alpha with f_j = 1 (OLS), (lambda_j + d) / (lambda_j + k) (Liu),
lambda_j / (lambda_j + k) (ridge) and 1 or 0 (PCR). One factorisation of H therefore
serves any number of measurement vectors (``fit_many``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from calib.analysis.identifiability import RANK_RTOL


@dataclass(frozen=True)
class LinearEstimate:
    method: str  # "ols", "liu", "ridge", "pcr"
    x: np.ndarray  # (m,) estimate, original units
    # (m, m) sampling covariance A cov(y) A^T = sigma2 A A^T of the linear map A (original
    # units); for the biased estimators this is the variance part only (no bias term), with
    # the data-dependent d or k held at the value used
    covariance: np.ndarray
    std_errors: np.ndarray  # sqrt(diag(covariance))
    sigma2: float  # noise variance used
    bias_parameter: float | None = None  # Liu d, ridge k, PCR component count
    notes: tuple[str, ...] = ()
    scale_parameter: float | None = None  # Liu's k (the paper's Eq. 11 has k = 1)
    linear_map: np.ndarray | None = None  # (m, n) A with x = A y, original units


class Estimator(Protocol):
    name: str

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate: ...

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray: ...


def scale_columns(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Hs, scale) with Hs = H / scale and scale the Euclidean column norms."""
    h = np.asarray(h, dtype=float)
    if h.ndim != 2:
        raise ValueError(f"H must be a 2-D (n, m) matrix, got shape {h.shape}")
    if not np.all(np.isfinite(h)):
        raise ValueError("H contains NaN or inf")
    scale = np.linalg.norm(h, axis=0)
    zero = np.flatnonzero(scale == 0)
    if zero.size:
        raise ValueError(f"column(s) {zero.tolist()} of H are zero: no pose moves those parameters")
    return h / scale, scale


@dataclass(frozen=True)
class Scaled:
    """The scaled problem: hs = h / scale and its thin SVD hs = u diag(s) vt."""

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

    @property
    def lambdas(self) -> np.ndarray:
        """Eigenvalues of Hs^T Hs (descending); the eigenvectors are the rows of vt."""
        return self.s**2

    def alpha(self, y: np.ndarray) -> np.ndarray:
        """OLS in canonical coordinates, Phi^T b_OLS, for y (n,) or (runs, n)."""
        return (y @ self.u) / self.s

    def ols(self, y: np.ndarray) -> np.ndarray:
        """OLS in scaled units for y (n,) or (runs, n) -> (m,) or (runs, m)."""
        return self.alpha(y) @ self.vt

    def rss(self, y: np.ndarray, b: np.ndarray) -> np.ndarray:
        r = y - b @ self.hs.T
        return np.sum(r * r, axis=-1)

    def ols_rss(self, y: np.ndarray, yu: np.ndarray | None = None) -> np.ndarray:
        """Residual sum of squares of the OLS fit (scalar or per run); ``yu``: the product
        ``y @ u`` when the caller has it (the same numbers, one product fewer)."""
        r = y - ((y @ self.u) if yu is None else yu) @ self.u.T
        return np.sum(r * r, axis=-1)

    def filtered(self, y: np.ndarray, f: np.ndarray) -> np.ndarray:
        """Phi diag(f) alpha in original units; f (m,) or (runs, m) for y (runs, n)."""
        return ((self.alpha(y) * f) @ self.vt) / self.scale

    def unscale_cov(self, cov_s: np.ndarray) -> np.ndarray:
        return cov_s / np.outer(self.scale, self.scale)


def prepare(h: np.ndarray, y: np.ndarray | None = None, many: bool = False) -> Scaled:
    """Validate H (and y, one vector or (runs, n) if ``many``) and scale; errors name the cause."""
    hs, scale = scale_columns(h)
    n, m = hs.shape
    if y is not None:
        y = np.asarray(y, dtype=float)
        if (y.ndim not in (1, 2)) if many else (y.ndim != 1):
            want = "(runs, n) or (n,)" if many else "a vector (n,)"
            raise ValueError(f"the measurements must be {want}, got shape {y.shape}")
        if y.shape[-1] != n:
            raise ValueError(f"y has {y.shape[-1]} entries per draw but H has {n} rows")
        if not np.all(np.isfinite(y)):
            raise ValueError("the measurements y contain NaN or inf")
    if n <= m:
        raise ValueError(
            f"{n} equations for {m} unknowns: a linear estimator needs more equations than "
            "unknowns (and n - m > 0 degrees of freedom for the noise variance)"
        )
    u, s, vt = np.linalg.svd(hs, full_matrices=False)
    if s[-1] <= RANK_RTOL * s[0]:
        raise ValueError(
            f"H is rank deficient (rank {int(np.sum(s > RANK_RTOL * s[0]))} of {m} columns): "
            "reconstruct an identifiable set first (calib.analysis.reconstruction)"
        )
    return Scaled(hs, scale, u, s, vt)


@dataclass(frozen=True)
class Draws:
    """Many measurement vectors y_i = y0 + e_i (a Monte Carlo over noise draws e_i on one H)
    as every spectral filter needs them: their products with the left singular vectors of
    the scaled problem and their OLS residual sums of squares, computed once for all the
    estimators that read them (``fit_draws``)."""

    h: np.ndarray  # (n, m) as given
    prob: Scaled
    yu: np.ndarray  # (runs, m) y_i @ u
    rss: np.ndarray  # (runs,) |y_i - u u^T y_i|^2

    @property
    def alpha(self) -> np.ndarray:
        """OLS in canonical coordinates, (runs, m)."""
        return self.yu / self.prob.s


class DrawEstimator(Protocol):
    """An estimator that reads a Monte Carlo's shared :class:`Draws` (OLS, Liu, paper Liu)."""

    def fit_draws(self, draws: Draws) -> np.ndarray: ...


def draws(h: np.ndarray, y0: np.ndarray, noise: np.ndarray, chunk: int = 2000) -> Draws:
    """:class:`Draws` of y0 (n,) plus every row of ``noise`` (runs, n), ``chunk`` rows at a
    time (no temporary larger than chunk x n).

    y_i @ u = y0 @ u + e_i @ u, and with r0 the OLS residual of y0 (orthogonal to the
    columns of H) the residual sum of squares is |r0|^2 + 2 r0.e_i + |e_i|^2 - |e_i @ u|^2:
    no (runs, n) residual is formed, and nothing cancels but |e_i|^2 - |e_i @ u|^2, whose
    ratio is about n / (n - m)."""
    prob = prepare(h, y0)
    y0 = np.asarray(y0, dtype=float)
    noise = np.atleast_2d(np.asarray(noise, dtype=float))
    if noise.ndim != 2 or noise.shape[1] != prob.n:
        raise ValueError(f"the noise must be (runs, {prob.n}), got shape {noise.shape}")
    if not np.all(np.isfinite(noise)):
        raise ValueError("the noise draws contain NaN or inf")
    y0u = y0 @ prob.u
    r0 = y0 - y0u @ prob.u.T
    yu = np.empty((len(noise), prob.m))
    rss = np.empty(len(noise))
    for lo in range(0, len(noise), chunk):
        e = noise[lo : lo + chunk]
        eu = e @ prob.u
        yu[lo : lo + chunk] = y0u + eu
        rss[lo : lo + chunk] = (
            r0 @ r0 + 2.0 * (e @ r0) + np.einsum("ij,ij->i", e, e) - np.einsum("ij,ij->i", eu, eu)
        )
    return Draws(np.asarray(h, dtype=float), prob, yu, rss)


def check_sigma2(sigma2: float) -> float:
    s2 = float(sigma2)
    if not (np.isfinite(s2) and s2 >= 0):
        raise ValueError(f"sigma2 must be a finite, non-negative variance, got {sigma2!r}")
    return s2


def residual_variance(prob: Scaled, y: np.ndarray, b_ols: np.ndarray | None = None) -> float:
    """Unbiased noise variance RSS / (n - m) from the OLS fit."""
    rss = prob.ols_rss(y) if b_ols is None else prob.rss(y, b_ols)
    return float(rss / (prob.n - prob.m))


def hkb_k(m: int, sigma2: np.ndarray | float, b: np.ndarray) -> np.ndarray:
    """Hoerl-Kennard-Baldwin k = m sigma^2 / |b_OLS|^2 (scaled); 1 when b_OLS = 0."""
    b2 = np.sum(np.asarray(b) ** 2, axis=-1)
    safe = np.where(b2 > 0, b2, 1.0)
    return np.where(b2 > 0, m * np.asarray(sigma2, dtype=float) / safe, 1.0)


def estimate_from_filter(
    method: str,
    prob: Scaled,
    y: np.ndarray,
    f: np.ndarray,
    sigma2: float,
    bias: float | None,
    notes: tuple[str, ...] = (),
    scale: float | None = None,
) -> LinearEstimate:
    """Package the spectral filter b = Phi diag(f) alpha(y) in original units."""
    x = prob.filtered(np.asarray(y, dtype=float)[None, :], f)[0]
    a_s = (prob.vt.T * (f / prob.s)) @ prob.u.T  # scaled units
    cov = prob.unscale_cov(sigma2 * ((prob.vt.T * (f / prob.s) ** 2) @ prob.vt))
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return LinearEstimate(
        method, x, cov, std, sigma2, bias, notes, scale, a_s / prob.scale[:, None]
    )
