"""Spearman's rank correlation and its two-sided p-value, as scipy.stats.spearmanr computes
them (average ranks for ties, Pearson's r of the ranks, Student's t with n - 2 degrees of
freedom), without importing scipy.stats: that import alone took about 1 s of a command that
otherwise answers in a fraction of it."""

from __future__ import annotations

import numpy as np
from scipy import special


def average_ranks(x: np.ndarray) -> np.ndarray:
    """Ranks 1..n of ``x`` (n,), ties given the mean of the ranks they span."""
    x = np.asarray(x, dtype=float)
    order = np.argsort(x, kind="mergesort")
    sorted_x = x[order]
    starts = np.r_[True, sorted_x[1:] != sorted_x[:-1]]
    group = np.cumsum(starts) - 1
    first = np.flatnonzero(starts)
    last = np.r_[first[1:], len(x)]  # one past each group's end
    ranks = np.empty(len(x))
    ranks[order] = 0.5 * (first + 1 + last)[group]
    return ranks


def spearman(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(rho, p) of ``a`` and ``b`` (n,); NaN for fewer than two points or a constant input."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n = len(a)
    if n <= 1 or np.all(a == a[0]) or np.all(b == b[0]):
        return float("nan"), float("nan")
    rs = np.corrcoef(np.vstack([average_ranks(a), average_ranks(b)]))[1, 0]
    dof = n - 2
    with np.errstate(divide="ignore"):
        t = rs * np.sqrt(np.clip(dof / ((rs + 1.0) * (1.0 - rs)), 0, None))
    return float(rs), float(2.0 * special.stdtr(dof, -np.abs(t)))
