"""The diagnosis's fitting problem: the residual fitted by a geometric correction plus
candidates' columns on training poses, its folds, and the held-out error of a fit.

The residual r (N poses, R rows) of the geometric calibration is fitted, on a set of training
poses, by a geometric correction (the identified parameters' columns G) plus the candidates'
columns X: r ~ G beta + X theta, linearised at the geometric estimate. Outer folds are
contiguous blocks of the measurement order (a drift must predict *later* poses) and random.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common.worker_processes import map_in_order, shared_array

SCHEMES = ("blocked", "random")
RCOND = 1e-10
# a candidate's column of which the geometry's projection leaves less than this share of its
# own norm is one the geometry spans: what is left is the round-off of the projection (the
# basis of ill-conditioned geometric columns holds their span to about eps x their condition
# number: a UR5's joint axis tilts, each a DH angle's twin, kept 4e-9 of themselves, and
# fitting that remainder gave a held-out RMS that differed in its third digit between BLAS
# kernels)
SPANNED = 1e-7


def fold_labels(time: np.ndarray, folds: int, scheme: str, seed: int = 0) -> np.ndarray:
    """Fold of each pose: contiguous blocks of the measurement order, or a seeded shuffle."""
    n = len(time)
    rank = np.empty(n, dtype=int)
    rank[np.argsort(time, kind="stable")] = np.arange(n)
    if scheme == "blocked":
        return rank * folds // n
    perm = np.random.default_rng(seed).permutation(n)
    out = np.empty(n, dtype=int)
    out[perm] = np.arange(n) % folds
    return out


def _orth(a: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the column space of ``a`` (rank-revealing SVD)."""
    if a.shape[1] == 0:
        return np.zeros((a.shape[0], 0))
    u, s, _ = np.linalg.svd(a, full_matrices=False)
    keep = s > RCOND * max(s[0], 1e-300)
    return u[:, keep]


def orth_and_pinv(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_orth(a)`` and ``np.linalg.pinv(a, rcond=RCOND)`` from one SVD (numpy's pinv
    arithmetic step for step, so the same numbers)."""
    if a.size == 0:
        return _orth(a), np.linalg.pinv(a, rcond=RCOND)
    u, s, vt = np.linalg.svd(a, full_matrices=False)
    q = u[:, s > RCOND * max(s[0], 1e-300)]
    large = s > RCOND * np.max(s)
    inv = np.divide(1, s, where=large, out=s.copy())
    inv[~large] = 0
    return q, np.matmul(vt.T, np.multiply(inv[:, None], u.T))


def _order(a: np.ndarray) -> str:
    return "F" if a.flags.f_contiguous and not a.flags.c_contiguous else "C"


@dataclass
class Problem:
    """The geometric residual and columns, with cached projection bases per training set."""

    r: np.ndarray  # (N, R), rejected rows zero
    geo: np.ndarray  # (N, R, p)
    _cache: dict = field(default_factory=dict)

    def rows(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g = self.geo[poses].reshape(-1, self.geo.shape[2])
        return g, self.residual_rows(poses)

    def residual_rows(self, poses: np.ndarray) -> np.ndarray:
        """The residual of these poses, flat (the second part of :meth:`rows`)."""
        return self.r[poses].reshape(-1)

    def projected_residual(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(r, r - Q Q^T r) of these poses' residual rows, cached with the basis."""
        key = ("rp", np.asarray(poses, bool).tobytes())
        if key not in self._cache:
            q, _ = self.basis(poses)
            rt = self.residual_rows(poses)
            self._cache[key] = (rt, rt - q @ (q.T @ rt))
        return self._cache[key]

    def basis(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Q, G^+) of the geometric columns of these poses."""
        key = np.asarray(poses, bool).tobytes()
        if key not in self._cache:
            self._cache[key] = self._made_basis(poses)
        return self._cache[key]

    def _made_basis(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g, _ = self.rows(poses)
        scale = np.linalg.norm(g, axis=0)
        scale[scale == 0] = 1.0
        q, gplus = orth_and_pinv(g / scale)
        return q, gplus / scale[:, None]

    def fill(self, sets: list[np.ndarray], workers: int) -> None:
        """The bases and projected residuals of ``sets`` (pose masks) into the cache, each set
        a task: with ``workers`` > 1 made side by side in forked workers, which write them
        into shared memory (the arithmetic of :meth:`basis` and :meth:`projected_residual`,
        so the same numbers)."""
        todo, seen = [], set()
        for poses in sets:
            key = np.asarray(poses, bool).tobytes()
            if key not in self._cache and key not in seen:
                seen.add(key)
                todo.append(np.asarray(poses, bool))
        if workers <= 1 or len(todo) <= 1:
            for poses in todo:
                self.projected_residual(poses)
            return
        p = self.geo.shape[2]
        # per set: room for Q (rows x at most p), G+ (p x rows) and the projected residual
        slots = [shared_array((3, int(poses.sum()) * self.r.shape[1] * p)) for poses in todo]

        def one(i: int) -> tuple[int, str, str]:
            q, gplus = self._made_basis(todo[i])
            rt = self.residual_rows(todo[i])
            rp = rt - q @ (q.T @ rt)
            for k, a in enumerate((q, gplus, rp)):
                slots[i][k, : a.size] = a.ravel(order="K")  # in its own memory order
            return q.shape[1], _order(q), _order(gplus)

        for poses, slot, (rank, q_order, g_order) in zip(
            todo, slots, map_in_order(one, len(todo), workers), strict=True
        ):
            n = int(poses.sum()) * self.r.shape[1]
            # views of the shared memory in the layout basis() makes (numpy's SVD gives a
            # column-major Q): a BLAS product's order of sums, so its last bits, follow it
            q = slot[0, : n * rank].reshape((n, rank), order=q_order)
            gplus = slot[1, : p * n].reshape((p, n), order=g_order)
            self._cache[poses.tobytes()] = (q, gplus)
            self._cache[("rp", poses.tobytes())] = (self.residual_rows(poses), slot[2, :n])


@dataclass(frozen=True)
class Fit:
    theta: np.ndarray  # (K,) effect parameters, SI
    beta: np.ndarray  # (p,) geometric correction, SI


def _flat(xs: list[np.ndarray], poses: np.ndarray) -> np.ndarray:
    if not xs:
        return np.zeros((int(np.sum(poses)) * 1, 0))
    return np.concatenate([x[poses] for x in xs], axis=2).reshape(-1, sum(x.shape[2] for x in xs))


def fit(
    prob: Problem, xs: list[np.ndarray], poses: np.ndarray, lower: np.ndarray | None = None
) -> Fit:
    """Least squares of r by G beta + X theta on ``poses``; ``lower`` bounds theta below."""
    q, gplus = prob.basis(poses)
    rt, rp = prob.projected_residual(poses)
    k = sum(x.shape[2] for x in xs)
    if k == 0:
        return Fit(np.zeros(0), gplus @ rt)
    return _solve(q, gplus, rt, rp, _flat(xs, poses).reshape(len(rt), k), lower)


def _solve(
    q: np.ndarray,
    gplus: np.ndarray,
    rt: np.ndarray,
    rp: np.ndarray,
    xt: np.ndarray,
    lower: np.ndarray | None = None,
) -> Fit:
    """:func:`fit` from the training set's basis ``q``, ``gplus``, residual ``rt`` and its
    projection ``rp``, and the candidates' columns ``xt`` (rows, k)."""
    k = xt.shape[1]
    xp = xt - q @ (q.T @ xt)
    scale = np.sqrt(np.add.reduce(xp * xp, axis=0))  # np.linalg.norm(xp, axis=0)'s arithmetic
    # a column the data does not see (a joint no load reaches, a harmonic of a joint that
    # did not turn, or one the geometry spans): its parameter stays 0, not 1 / 0
    own = np.sqrt(np.add.reduce(xt * xt, axis=0))
    live = (scale > RCOND * max(float(scale.max(initial=0.0)), 1e-300)) & (scale > SPANNED * own)
    theta = np.zeros(k)
    if np.any(live):
        # every column seen (the usual case): the columns themselves, not a copy of them
        a, sc = (xp / scale, scale) if live.all() else (xp[:, live] / scale[live], scale[live])
        if lower is not None and np.any(np.isfinite(lower[live])):
            from scipy.optimize import lsq_linear  # lazy: scipy.optimize costs 0.7 s

            res = lsq_linear(a, rp, bounds=(lower[live] * sc, np.inf), method="bvls")
            theta[live] = res.x / sc
        else:
            theta[live] = np.linalg.lstsq(a, rp, rcond=RCOND)[0] / sc
    return Fit(theta, gplus @ (rt - xt @ theta))


def heldout_sse(prob: Problem, xs: list[np.ndarray], f: Fit, poses: np.ndarray) -> np.ndarray:
    """Per-pose sum of squared residuals on ``poses`` after the fit ``f``."""
    xv = np.concatenate([x[poses] for x in xs], axis=2) if xs else None
    return _sse(prob.r[poses], prob.geo[poses], xv, f)


def _sse(r: np.ndarray, geo: np.ndarray, x: np.ndarray | None, f: Fit) -> np.ndarray:
    """:func:`heldout_sse` from the poses' residual ``r`` (n, R), geometric columns ``geo``
    (n, R, p) and candidates' columns ``x`` (n, R, k) or None."""
    e = r - geo @ f.beta
    if x is not None:
        e = e - x @ f.theta
    return np.sum(e**2, axis=1)
