"""The Liu estimator (Liu 1993; the first paper's Eqs. 11-14) and its Liu-type scale k.

On the column-scaled H (unit columns) with H^T H = Phi diag(lambda) Phi^T and
alpha = Phi^T b_OLS, the Liu-type family (Liu 2003) is

    b = (H^T H + k I)^-1 (H^T y + d b_OLS),
    i.e. alpha_L,j = (lambda_j + d) / (lambda_j + k) alpha_j,

a linear map A = (H^T H + k I)^-1 (H^T + d (H^T H)^-1 H^T) of y. Its mean square error

    MSE(d) = sigma^2 sum (lambda + d)^2 / (lambda (lambda + k)^2)
             + (d - k)^2 sum alpha^2 / (lambda + k)^2

is a convex quadratic in d, minimised by d = sum (k alpha^2 - sigma^2) / (lambda + k)^2 /
sum (sigma^2 + lambda alpha^2) / (lambda (lambda + k)^2). With k = 1 these are exactly the
paper's Eqs. 11, 13 and 14 (``k=1.0`` gives the paper's estimator literally).

The scale k. The paper's "1" is measured against the eigenvalues of H^T H, so its effect
depends on the units of H: in the paper's mm and deg most eigenvalues dwarf it, and Liu
departs from OLS only along the worst-determined directions; on a column-scaled H the
eigenvalues are those of a correlation matrix (they sum to the parameter count) and k = 1
shrinks well-determined directions as well. So the default k is the unit-free
Hoerl-Kennard-Baldwin value k = m sigma^2 / |b_OLS|^2 (scaled), the standard choice of the
ridge literature.

Clipping. The paper requires 0 < d < 1 (0 < d < k). When the optimal d falls outside, it is
clipped to [0, k] and a note says so: d = k is OLS, d = 0 is ridge with the same k (for k = 1
the ridge-like (H^T H + I)^-1 H^T y). As the MSE is a convex quadratic in d, the clipped value
is the best d inside the interval; a d > k would extrapolate beyond OLS (amplify alpha) and a
d < 0 shrink beyond ridge, neither of which Liu's derivation covers. A fixed ``d`` is used
as given.

The noise variance. ``sigma2_rule="paper"`` takes Eq. 13 as written, sigma^2 = RSS / n (the
maximum-likelihood value, low by the factor (n - m) / n); ``"unbiased"`` (default) takes
RSS / (n - m). A smaller sigma^2 raises d, i.e. shrinks less. Both use the OLS residuals.
The covariance holds d and k at the values used (their own sampling spread is ignored). For
a fixed 0 <= d <= k it never exceeds the OLS covariance. In a Monte Carlo, where d (and k)
are re-estimated in every run, their run-to-run spread also moves the well-determined
directions, which carry most of the signal: with k = 1 on a scaled H this can spread the
well-determined parameters more than OLS does, while the total over the scaled problem
still shrinks.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from calib.estimators.linear import (
    Draws,
    LinearEstimate,
    Scaled,
    check_sigma2,
    estimate_from_filter,
    hkb_k,
    prepare,
)


def liu_d_optimal(
    lambdas: np.ndarray, alpha: np.ndarray, sigma2: np.ndarray | float, k: np.ndarray | float = 1.0
) -> np.ndarray:
    """The MSE-optimal d (Eq. 14 for k = 1), vectorised over leading axes of alpha."""
    a2 = np.asarray(alpha, dtype=float) ** 2
    s2 = np.asarray(sigma2, dtype=float)[..., None]
    kk = np.asarray(k, dtype=float)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        num = np.sum((kk * a2 - s2) / (lambdas + kk) ** 2, axis=-1)
        den = np.sum((s2 + lambdas * a2) / (lambdas * (lambdas + kk) ** 2), axis=-1)
        return num / den


def liu_mse(
    lambdas: np.ndarray, alpha: np.ndarray, sigma2: float, d: float, k: float = 1.0
) -> float:
    """Mean square error of the estimate for given d and k (Eq. 13 for k = 1)."""
    var = sigma2 * np.sum((lambdas + d) ** 2 / (lambdas * (lambdas + k) ** 2))
    bias = (d - k) ** 2 * np.sum(np.asarray(alpha) ** 2 / (lambdas + k) ** 2)
    return float(var + bias)


class Liu:
    name = "liu"

    def __init__(
        self,
        d: float | None = None,
        k: float | Literal["hkb"] = "hkb",
        sigma2_rule: Literal["paper", "unbiased"] = "unbiased",
    ) -> None:
        if sigma2_rule not in ("paper", "unbiased"):
            raise ValueError(f"sigma2_rule must be 'paper' or 'unbiased', got {sigma2_rule!r}")
        if k != "hkb" and not (isinstance(k, (int, float)) and np.isfinite(k) and k > 0):
            raise ValueError(f"Liu k must be 'hkb' or a positive number, got {k!r}")
        if d is not None and not np.isfinite(d):
            raise ValueError(f"Liu d must be a finite number or None, got {d!r}")
        self.d = d
        self.k = k
        self.sigma2_rule = sigma2_rule

    def _sigma2(self, prob: Scaled, ys: np.ndarray, yu: np.ndarray | None = None) -> np.ndarray:
        return self._sigma2_of_rss(prob, prob.ols_rss(ys, yu))

    def _sigma2_of_rss(self, prob: Scaled, rss: np.ndarray) -> np.ndarray:
        return rss / (prob.n if self.sigma2_rule == "paper" else prob.n - prob.m)

    def _d_and_k(self, prob: Scaled, alpha: np.ndarray, s2: np.ndarray):
        """k, raw d and the d used (each (runs,)) for alpha (runs, m)."""
        if self.k == "hkb":
            k = hkb_k(prob.m, s2, alpha)
        else:
            k = np.full(alpha.shape[0], float(self.k))
        if self.d is not None:
            d_raw = np.full(alpha.shape[0], float(self.d))
            return k, d_raw, d_raw
        d_raw = np.broadcast_to(np.asarray(liu_d_optimal(prob.lambdas, alpha, s2, k)), k.shape)
        d = np.where(np.isfinite(d_raw), np.clip(d_raw, 0.0, k), k)
        return k, d_raw, d

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        y = np.asarray(y, dtype=float)
        s2 = float(self._sigma2(prob, y)) if sigma2 is None else check_sigma2(sigma2)
        alpha = prob.alpha(y)[None, :]
        k, d_raw, d = (float(v[0]) for v in self._d_and_k(prob, alpha, np.array([s2])))
        notes = []
        if not np.isfinite(d_raw):
            notes.append(f"Liu d from Eq. 14 is undefined ({d_raw}): d = k = {k:.4g}, i.e. OLS")
        elif d != d_raw:
            what = "OLS" if d == k else f"ridge with k = {k:.4g}"
            notes.append(
                f"Liu d from Eq. 14 was {d_raw:.4g}, outside (0, {k:.4g}): "
                f"clipped to {d:.4g} ({what})"
            )
        notes.append(f"k = {k:.4g} ({'Hoerl-Kennard-Baldwin' if self.k == 'hkb' else 'given'})")
        f = (prob.lambdas + d) / (prob.lambdas + k)
        return estimate_from_filter(self.name, prob, y, f, s2, d, tuple(notes), k)

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Estimates (runs, m) for ys (runs, n): one factorisation, sigma^2, k, d per run."""
        prob = prepare(h, ys, many=True)
        ys = np.atleast_2d(np.asarray(ys, dtype=float))
        yu = ys @ prob.u  # once for alpha, sigma^2 and the estimate (the same numbers)
        return self._filtered(prob, yu / prob.s, self._sigma2(prob, ys, yu))

    def fit_draws(self, draws: Draws) -> np.ndarray:
        """:meth:`fit_many` of the draws' measurement vectors, from their shared products."""
        return self._filtered(draws.prob, draws.alpha, self._sigma2_of_rss(draws.prob, draws.rss))

    def _filtered(self, prob: Scaled, alpha: np.ndarray, s2: np.ndarray) -> np.ndarray:
        """Estimates (runs, m) from alpha (runs, m) and sigma^2 (runs,): k and d per run."""
        k, _, d = self._d_and_k(prob, alpha, s2)
        f = (prob.lambdas[None, :] + d[:, None]) / (prob.lambdas[None, :] + k[:, None])
        return ((alpha * f) @ prob.vt) / prob.scale  # prob.filtered(ys, f)
