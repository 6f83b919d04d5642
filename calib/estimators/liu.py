"""The Liu estimator (Liu 1993, the first paper's Eqs. 11-14) and its Liu-type scale k.

On the column-scaled H (unit columns) with H^T H = Phi diag(lambda) Phi^T and
alpha = Phi^T b_OLS, the Liu-type family (Liu 2003) is

    b = (H^T H + k I)^-1 (H^T y + d b_OLS),
    i.e. alpha'_j = (lambda_j + d) / (lambda_j + k) alpha_j,

and the d that minimises its mean square error

    MSE(d) = sigma^2 sum (lambda + d)^2 / (lambda (lambda + k)^2)
             + (d - k)^2 sum alpha^2 / (lambda + k)^2

is d = sum (k alpha^2 - sigma^2) / (lambda + k)^2 / sum (sigma^2 + lambda alpha^2) /
(lambda (lambda + k)^2). With k = 1 these are exactly the paper's Eqs. 11, 13 and 14.

The scale k. The paper's "1" is measured against the eigenvalues of H^T H, so its effect
depends on the units of H: in the paper's mm and deg most eigenvalues dwarf it, and Liu
departs from OLS only along the worst-determined directions; on a column-scaled H the
eigenvalues are those of a correlation matrix (they sum to the parameter count) and k = 1
shrinks well-determined directions as well. So the default k is the unit-free
Hoerl-Kennard-Baldwin value k = m sigma^2 / |b_OLS|^2 (scaled), the standard choice of the
ridge literature; ``k=1.0`` gives the paper's estimator literally. When the optimal d falls
outside (0, k) it is clipped to that interval (d = k is OLS, d = 0 ridge with that k; the MSE
is a convex quadratic in d, so the clipped value is the best one inside) and a note says so.
sigma^2 is RSS/(n - m) ("unbiased") or RSS/n as the paper writes it ("paper").
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from calib.estimators.linear import LinearEstimate, estimate_from_map, prepare


def liu_d_optimal(
    lambdas: np.ndarray, alpha: np.ndarray, sigma2: np.ndarray | float, k: np.ndarray | float = 1.0
) -> np.ndarray:
    """The MSE-optimal d (Eq. 14 for k = 1), vectorised over leading axes of alpha."""
    a2 = alpha**2
    s2 = np.asarray(sigma2, dtype=float)[..., None]
    kk = np.asarray(k, dtype=float)[..., None]
    num = np.sum((kk * a2 - s2) / (lambdas + kk) ** 2, axis=-1)
    den = np.sum((s2 + lambdas * a2) / (lambdas * (lambdas + kk) ** 2), axis=-1)
    return num / den


def liu_mse(
    lambdas: np.ndarray, alpha: np.ndarray, sigma2: float, d: float, k: float = 1.0
) -> float:
    """Mean square error of the estimate for given d and k (Eq. 13 for k = 1)."""
    var = sigma2 * np.sum((lambdas + d) ** 2 / (lambdas * (lambdas + k) ** 2))
    bias = (d - k) ** 2 * np.sum(alpha**2 / (lambdas + k) ** 2)
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
        if k != "hkb" and not (isinstance(k, (int, float)) and k > 0):
            raise ValueError(f"k must be 'hkb' or a positive number, got {k!r}")
        self.d = d
        self.k = k
        self.sigma2_rule = sigma2_rule

    def _terms(self, prob, ys: np.ndarray):
        """alpha (runs, m), sigma^2 (runs,), k (runs,) for one or many measurement vectors."""
        alpha = (ys @ prob.u) / prob.s
        rss = prob.rss(ys, alpha @ prob.vt)
        s2 = rss / (prob.n if self.sigma2_rule == "paper" else prob.n - prob.m)
        if self.k == "hkb":
            k = prob.m * s2 / np.sum(alpha**2, axis=-1)
        else:
            k = np.full(np.shape(s2), float(self.k))
        return alpha, s2, k

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        lam = prob.s**2
        alpha, s2_est, k = self._terms(prob, np.asarray(y, dtype=float))
        s2 = float(s2_est) if sigma2 is None else float(sigma2)
        k = float(k)
        notes: list[str] = []
        if self.d is None:
            d_raw = float(liu_d_optimal(lam, alpha, s2, k))
            d = float(np.clip(d_raw, 0.0, k))
            if d != d_raw:
                notes.append(f"optimal d = {d_raw:.4g} lies outside (0, k = {k:.4g}): clipped")
        else:
            d = float(self.d)
        notes.append(f"k = {k:.4g} ({'Hoerl-Kennard-Baldwin' if self.k == 'hkb' else 'given'})")
        a_s = (prob.vt.T * ((lam + d) / (lam + k) / prob.s)) @ prob.u.T
        return estimate_from_map(self.name, prob, a_s, y, s2, d, tuple(notes), k)

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        prob = prepare(h, ys)
        ys = np.atleast_2d(np.asarray(ys, dtype=float))
        lam = prob.s**2
        alpha, s2, k = self._terms(prob, ys)
        if self.d is None:
            d = np.clip(liu_d_optimal(lam, alpha, s2, k), 0.0, k)
        else:
            d = np.full(len(ys), float(self.d))
        shrink = (lam[None, :] + d[:, None]) / (lam[None, :] + k[:, None])
        return ((alpha * shrink) @ prob.vt) / prob.scale
