"""Ordinary least squares on the column-scaled H (via its SVD)."""

from __future__ import annotations

import numpy as np

from calib.estimators.linear import LinearEstimate, estimate_from_map, prepare, residual_variance


class OLS:
    name = "ols"

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        a_s = (prob.vt.T / prob.s) @ prob.u.T
        s2 = residual_variance(prob, y, a_s @ y) if sigma2 is None else float(sigma2)
        return estimate_from_map(self.name, prob, a_s, y, s2, None)

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        prob = prepare(h, ys)
        return prob.ols(np.atleast_2d(ys)) / prob.scale
