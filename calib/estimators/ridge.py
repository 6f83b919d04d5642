"""Ridge regression on the scaled H, k by Hoerl-Kennard-Baldwin or generalised cross-validation.

b_k = (H^T H + k I)^-1 H^T y. HKB: k = m sigma^2 / |b_OLS|^2 (scaled units). GCV: k minimises
n |y - H b_k|^2 / (n - tr S_k)^2, S_k = H (H^T H + k I)^-1 H^T, over log k (grid, then refined).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.optimize import minimize_scalar

from calib.estimators.linear import LinearEstimate, estimate_from_map, prepare, residual_variance


def gcv_score(s: np.ndarray, uty: np.ndarray, resid_out: float, n: int, k: float) -> float:
    """GCV(k) from the SVD: uty = U^T y, resid_out = |y|^2 - |U^T y|^2."""
    f = s**2 / (s**2 + k)
    rss = float(np.sum(((1 - f) * uty) ** 2) + resid_out)
    return n * rss / (n - float(np.sum(f))) ** 2


class Ridge:
    name = "ridge"

    def __init__(self, rule: Literal["hkb", "gcv"] = "hkb", k: float | None = None) -> None:
        if rule not in ("hkb", "gcv"):
            raise ValueError(f"ridge rule must be 'hkb' or 'gcv', got {rule!r}")
        self.rule = rule
        self.k = k

    def _k(self, prob, y: np.ndarray, s2: float) -> float:
        if self.k is not None:
            return float(self.k)
        b = prob.ols(y)
        if self.rule == "hkb":
            return float(prob.m * s2 / float(b @ b))
        uty = prob.u.T @ y
        out = float(y @ y - uty @ uty)
        grid = np.logspace(-10, 4, 141) * prob.s[0] ** 2
        scores = [gcv_score(prob.s, uty, out, prob.n, k) for k in grid]
        i = int(np.argmin(scores))
        lo, hi = np.log(grid[max(i - 1, 0)]), np.log(grid[min(i + 1, len(grid) - 1)])
        res = minimize_scalar(
            lambda t: gcv_score(prob.s, uty, out, prob.n, float(np.exp(t))),
            bounds=(lo, hi),
            method="bounded",
        )
        return float(np.exp(res.x))

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        s2 = residual_variance(prob, y, prob.ols(y)) if sigma2 is None else float(sigma2)
        k = self._k(prob, y, s2)
        a_s = (prob.vt.T * (prob.s / (prob.s**2 + k))) @ prob.u.T
        return estimate_from_map(self.name, prob, a_s, y, s2, k)

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        return np.array([self.fit(h, y).x for y in np.atleast_2d(ys)])
