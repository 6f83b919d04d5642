"""Ordinary least squares on the column-scaled H.

Solved through the thin SVD of Hs (as ``numpy.linalg.lstsq`` does): b = V diag(1/s) U^T y,
mapped back as x = b / scale. The noise variance is the unbiased RSS / (n - m) unless given;
the covariance is sigma^2 (H^T H)^-1 in the original units.
"""

from __future__ import annotations

import numpy as np

from calib.estimators.linear import (
    Draws,
    LinearEstimate,
    check_sigma2,
    estimate_from_filter,
    prepare,
    residual_variance,
)


class OLS:
    name = "ols"

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        y = np.asarray(y, dtype=float)
        s2 = residual_variance(prob, y) if sigma2 is None else check_sigma2(sigma2)
        return estimate_from_filter(self.name, prob, y, np.ones(prob.m), s2, None)

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Estimates (runs, m) for measurement vectors ys (runs, n), one factorisation of H."""
        prob = prepare(h, ys, many=True)
        return prob.filtered(np.atleast_2d(np.asarray(ys, dtype=float)), np.ones(prob.m))

    def fit_draws(self, draws: Draws) -> np.ndarray:
        """:meth:`fit_many` of the draws' measurement vectors, from their shared products."""
        return (draws.alpha @ draws.prob.vt) / draws.prob.scale
