"""The paper's Liu estimator literally: Eq. 11 with k = 1 on H in the paper's own units.

Huang et al. (2018) write b = (H^T H + I)^-1 (H^T y + d b_OLS) with H and y in millimetres and
degrees (or radians: the paper does not say), not column-scaled. The "1" is then measured
against eigenvalues of H^T H in those units, so the estimate depends on the unit chosen for
angles: a column in degrees is pi/180 times smaller than in radians, its eigen-directions
weaker, and Liu shrinks them more. This estimator makes that choice explicit
(``angle_unit``) so that both readings can be shown beside the unit-free Liu-type estimator
of calib.estimators.liu. d is Eq. 14 (the MSE-optimal d for k = 1), clipped to [0, 1].

The noise variance of Eqs. 13-14 is the paper's sigma^2 = RSS / n (Eq. 13: the trace of the
OLS residual's outer product over n); ``sigma2_rule="unbiased"`` takes RSS / (n - m) instead
(a larger sigma^2, a smaller d: more shrinkage).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from calib.estimators.linear import Draws, LinearEstimate, check_sigma2
from calib.estimators.liu import liu_d_optimal

ANGLE_UNITS = {"deg": np.pi / 180.0, "rad": 1.0}


class LiuPaperUnits:
    name = "liu_paper"

    def __init__(
        self,
        angle_unit: str = "deg",
        k: float = 1.0,
        is_angle=None,
        sigma2_rule: Literal["paper", "unbiased"] = "paper",
    ) -> None:
        if sigma2_rule not in ("paper", "unbiased"):
            raise ValueError(f"sigma2_rule must be 'paper' or 'unbiased', got {sigma2_rule!r}")
        if angle_unit not in ANGLE_UNITS:
            raise ValueError(f"angle_unit must be one of {sorted(ANGLE_UNITS)}, got {angle_unit!r}")
        if not (np.isfinite(k) and k > 0):
            raise ValueError(f"k must be a positive number, got {k!r}")
        self.angle_unit = angle_unit
        self.k = float(k)
        self.is_angle = None if is_angle is None else np.asarray(is_angle, dtype=bool)
        self.sigma2_rule = sigma2_rule

    def _dof(self, n: int, m: int) -> int:
        """The divisor of the residual sum of squares: n (Eq. 13) or n - m."""
        return n if self.sigma2_rule == "paper" else n - m

    def _units(self, m: int) -> np.ndarray:
        """Paper units per SI unit of each parameter: 1e3 (mm per m) or deg/rad per rad."""
        if self.is_angle is None or self.is_angle.shape != (m,):
            raise ValueError(
                "the paper-units Liu needs to know which of the H columns are angles "
                f"(is_angle with {m} entries)"
            )
        return np.where(self.is_angle, 1.0 / ANGLE_UNITS[self.angle_unit], 1e3)

    def _svd(self, h: np.ndarray):
        """(units, u, s, vt): paper units per SI unit and the thin SVD of H in paper units."""
        h = np.asarray(h, dtype=float)
        n, m = h.shape
        if n <= m:
            raise ValueError(f"{n} equations for {m} unknowns: Liu needs more equations")
        units = self._units(m)
        hp = h * 1e3 / units  # mm of target per paper unit of parameter
        return (units, *np.linalg.svd(hp, full_matrices=False))

    def _solve(self, h: np.ndarray, ys: np.ndarray):
        units, u, s, vt = self._svd(h)
        n, m = u.shape
        yp = np.atleast_2d(ys) * 1e3  # mm
        yu = yp @ u  # once for alpha and the residual
        rss = np.sum((yp - yu @ u.T) ** 2, axis=1)
        x, d, s2, f = self._filtered(yu / s, rss / self._dof(n, m), s**2, vt, units)
        return x, d, s2, (u, s, vt, units, f)

    def _filtered(
        self, alpha: np.ndarray, s2: np.ndarray, lam: np.ndarray, vt: np.ndarray, units: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(x SI, d, sigma^2, filter) per run from alpha (runs, m) and sigma^2 in mm^2."""
        d = liu_d_optimal(lam, alpha, s2, self.k)
        d = np.where(np.isfinite(d), np.clip(d, 0.0, self.k), self.k)
        f = (lam[None, :] + d[:, None]) / (lam[None, :] + self.k)
        x_paper = (alpha * f) @ vt
        return x_paper / units, d, s2, f

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        x, d, s2, (u, s, vt, units, f) = self._solve(h, y)
        # sigma^2 in SI (m^2) as every estimate states it: the fit's own is in mm^2
        s2v = float(s2[0]) * 1e-6 if sigma2 is None else check_sigma2(sigma2)
        # covariance of x = A y with A = V diag(f / s) U^T (paper units), then SI
        cov_p = s2v * 1e6 * ((vt.T * (f[0] / s) ** 2) @ vt)
        cov = cov_p / np.outer(units, units)
        notes = (
            f"the paper's Eq. 11 literally: k = {self.k:g} on H in mm and {self.angle_unit}",
            f"d = {float(d[0]):.4g}",
            "sigma^2 = RSS / n (Eq. 13)"
            if self.sigma2_rule == "paper"
            else "sigma^2 = RSS / (n - m)",
        )
        a = (vt.T * (f[0] / s)) @ u.T * 1e3 / units[:, None]
        return LinearEstimate(
            self.name,
            x[0],
            cov,
            np.sqrt(np.clip(np.diag(cov), 0, None)),
            s2v,
            float(d[0]),
            notes,
            self.k,
            a,
        )

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        return self._solve(h, ys)[0]

    def fit_draws(self, draws: Draws) -> np.ndarray:
        """:meth:`fit_many` of the draws' measurement vectors, from their shared products:
        H in paper units has the column space of the scaled H, so each draw's products with
        its left singular vectors are the shared ones turned by w = u_s^T u (m x m), and its
        residual sum of squares is the shared one (in mm^2)."""
        units, u, s, vt = self._svd(draws.h)
        n, m = u.shape
        w = draws.prob.u.T @ u
        alpha = (draws.yu @ w) * 1e3 / s
        return self._filtered(alpha, draws.rss * 1e6 / self._dof(n, m), s**2, vt, units)[0]
