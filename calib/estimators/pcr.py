"""Principal components regression: OLS restricted to the leading eigen-directions of H^T H.

Components whose eigenvalue is below ``rtol`` times the largest are discarded (or a fixed
``n_components`` is kept); the estimate lies in the span of the kept eigenvectors.
"""

from __future__ import annotations

import numpy as np

from calib.estimators.linear import LinearEstimate, estimate_from_map, prepare, residual_variance


class PCR:
    name = "pcr"

    def __init__(self, n_components: int | None = None, rtol: float = 1e-6) -> None:
        self.n_components = n_components
        self.rtol = rtol

    def _keep(self, s: np.ndarray) -> int:
        if self.n_components is not None:
            if not 1 <= self.n_components <= s.size:
                raise ValueError(f"n_components must be in 1..{s.size}, got {self.n_components}")
            return int(self.n_components)
        return int(np.sum(s**2 > self.rtol * s[0] ** 2))

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        r = self._keep(prob.s)
        s2 = residual_variance(prob, y, prob.ols(y)) if sigma2 is None else float(sigma2)
        a_s = (prob.vt[:r].T / prob.s[:r]) @ prob.u[:, :r].T
        return estimate_from_map(self.name, prob, a_s, y, s2, float(r))

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        prob = prepare(h, ys)
        r = self._keep(prob.s)
        ys = np.atleast_2d(ys)
        return (((ys @ prob.u[:, :r]) / prob.s[:r]) @ prob.vt[:r]) / prob.scale
