"""Principal components regression: OLS restricted to the leading eigen-directions of Hs^T Hs.

By default the components whose eigenvalue is at most ``rtol`` times the largest are
discarded (rtol = 1e-6, i.e. a condition number of Hs above 1000), the others kept; or a
fixed ``n_components`` is kept. The estimate lies in the span of the kept eigenvectors;
``bias_parameter`` records their count. The noise variance comes from the full OLS fit
(RSS / (n - m)), which stays unbiased whatever the truncation.
"""

from __future__ import annotations

import numpy as np

from calib.estimators.linear import (
    LinearEstimate,
    check_sigma2,
    estimate_from_filter,
    prepare,
    residual_variance,
)


class PCR:
    name = "pcr"

    def __init__(self, n_components: int | None = None, rtol: float = 1e-6) -> None:
        if n_components is not None and (int(n_components) != n_components or n_components < 1):
            raise ValueError(f"n_components must be a positive integer, got {n_components!r}")
        if not (np.isfinite(rtol) and 0 <= rtol < 1):
            raise ValueError(f"rtol must lie in [0, 1), got {rtol!r}")
        self.n_components = n_components
        self.rtol = rtol

    def _keep(self, lambdas: np.ndarray) -> int:
        if self.n_components is not None:
            if self.n_components > lambdas.size:
                raise ValueError(
                    f"n_components = {self.n_components} exceeds the {lambdas.size} unknowns"
                )
            return int(self.n_components)
        return int(np.sum(lambdas > self.rtol * lambdas[0]))

    def _filter(self, lambdas: np.ndarray) -> np.ndarray:
        f = np.zeros(lambdas.size)
        f[: self._keep(lambdas)] = 1.0  # eigenvalues come in descending order
        return f

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        y = np.asarray(y, dtype=float)
        s2 = residual_variance(prob, y) if sigma2 is None else check_sigma2(sigma2)
        f = self._filter(prob.lambdas)
        r = int(f.sum())
        notes = ()
        if r < prob.m:
            lam = prob.lambdas
            notes = (
                f"kept {r} of {prob.m} components; discarded eigenvalues "
                f"{lam[r]:.3g}..{lam[-1]:.3g} (lambda_max = {lam[0]:.3g})",
            )
        return estimate_from_filter(self.name, prob, y, f, s2, float(r), notes)

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Estimates (runs, m) for ys (runs, n) with one factorisation of H."""
        prob = prepare(h, ys, many=True)
        ys = np.atleast_2d(np.asarray(ys, dtype=float))
        return prob.filtered(ys, self._filter(prob.lambdas))
