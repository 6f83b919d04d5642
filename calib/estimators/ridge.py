"""Ridge regression on the scaled H, k by Hoerl-Kennard-Baldwin or generalised cross-validation.

b_k = (H^T H + k I)^-1 H^T y, i.e. alpha_j -> lambda_j / (lambda_j + k) alpha_j.

* ``rule="hkb"`` (default): k = m sigma^2 / |b_OLS|^2 (scaled units, sigma^2 = RSS / (n - m)),
  Hoerl, Kennard & Baldwin (1975).
* ``rule="gcv"``: k minimises GCV(k) = n |y - H b_k|^2 / (n - tr S_k)^2 with
  S_k = H (H^T H + k I)^-1 H^T (Golub, Heath & Wahba 1979): a log grid of k from 1e-10 to
  1e4 times lambda_max, refined by a bounded scalar minimisation on log k around the best
  grid point.
* ``k=...``: a fixed k (k -> 0 is OLS).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from calib.estimators.linear import (
    LinearEstimate,
    Scaled,
    check_sigma2,
    estimate_from_filter,
    hkb_k,
    prepare,
)

GCV_GRID = np.logspace(-10, 4, 141)  # times lambda_max


def gcv_score(s: np.ndarray, uty: np.ndarray, resid_out: float, n: int, k: float) -> float:
    """GCV(k) from the SVD: uty = U^T y, resid_out = |y - U U^T y|^2 (the OLS RSS)."""
    f = s**2 / (s**2 + k)
    rss = float(np.sum(((1 - f) * uty) ** 2) + resid_out)
    return n * rss / (n - float(np.sum(f))) ** 2


def gcv_k(prob: Scaled, ys: np.ndarray) -> np.ndarray:
    """The GCV-optimal k for each row of ys (runs, n): grid on all runs at once, then refine."""
    from scipy.optimize import minimize_scalar  # lazy: only the GCV rule needs it

    lam = prob.lambdas
    grid = GCV_GRID * lam[0]
    f = lam[None, :] / (lam[None, :] + grid[:, None])  # (G, m)
    w, dof2 = ((1 - f) ** 2).T, (prob.n - f.sum(axis=1)) ** 2
    ks = np.empty(len(ys))
    for r, y in enumerate(ys):  # row by row: a run's k does not depend on the other runs
        uty, out = y @ prob.u, float(prob.ols_rss(y))
        scores = prob.n * ((uty**2) @ w + out) / dof2
        i = int(np.argmin(scores))
        lo, hi = np.log(grid[max(i - 1, 0)]), np.log(grid[min(i + 1, len(grid) - 1)])
        res = minimize_scalar(
            lambda t, uty=uty, out=out: gcv_score(prob.s, uty, out, prob.n, float(np.exp(t))),
            bounds=(lo, hi),
            method="bounded",
            options={"xatol": 1e-8},
        )
        better = res.fun <= scores[i]
        ks[r] = float(np.exp(res.x)) if better else float(grid[i])
    return ks


class Ridge:
    name = "ridge"

    def __init__(self, rule: Literal["hkb", "gcv"] = "hkb", k: float | None = None) -> None:
        if rule not in ("hkb", "gcv"):
            raise ValueError(f"ridge rule must be 'hkb' or 'gcv', got {rule!r}")
        if k is not None and not (np.isfinite(k) and k >= 0):
            raise ValueError(f"ridge k must be a finite, non-negative number, got {k!r}")
        self.rule = rule
        self.k = k

    def _k(self, prob: Scaled, ys: np.ndarray, s2: np.ndarray) -> np.ndarray:
        if self.k is not None:
            return np.full(len(ys), float(self.k))
        if self.rule == "hkb":
            return hkb_k(prob.m, s2, prob.alpha(ys))  # |alpha| = |b_OLS| (Phi orthogonal)
        return gcv_k(prob, ys)

    def fit(self, h: np.ndarray, y: np.ndarray, sigma2: float | None = None) -> LinearEstimate:
        prob = prepare(h, y)
        y = np.asarray(y, dtype=float)
        s2_ols = float(prob.ols_rss(y)) / (prob.n - prob.m)
        s2 = s2_ols if sigma2 is None else check_sigma2(sigma2)
        k = float(self._k(prob, y[None, :], np.array([s2]))[0])
        rule = "given" if self.k is not None else self.rule
        f = prob.lambdas / (prob.lambdas + k)
        return estimate_from_filter(self.name, prob, y, f, s2, k, (f"k = {k:.4g} ({rule})",))

    def fit_many(self, h: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """Estimates (runs, m) for ys (runs, n): one factorisation, k chosen per run."""
        prob = prepare(h, ys, many=True)
        ys = np.atleast_2d(np.asarray(ys, dtype=float))
        k = self._k(prob, ys, prob.ols_rss(ys) / (prob.n - prob.m))
        return prob.filtered(ys, prob.lambdas[None, :] / (prob.lambdas[None, :] + k[:, None]))
