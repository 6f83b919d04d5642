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

from calib.diagnosis.basis import PINV_BUDGET, RCOND, Basis, make_basis
from common.worker_processes import map_in_order, shared_array

SCHEMES = ("blocked", "random")
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


def _order(a: np.ndarray | None) -> str | None:
    """The memory order of ``a`` (None for none)."""
    if a is None:
        return None
    return "F" if a.flags.f_contiguous and not a.flags.c_contiguous else "C"


@dataclass
class Problem:
    """The geometric residual and columns, with cached projection bases per training set."""

    r: np.ndarray  # (N, R), rejected rows zero
    geo: np.ndarray  # (N, R, p)
    _cache: dict = field(default_factory=dict)
    _pinv_bytes: int = 0  # of the pseudo-inverses kept in the cache

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
            q = self.basis(poses)
            rt = self.residual_rows(poses)
            self._cache[key] = (rt, rt - q @ (q.T @ rt))
        return self._cache[key]

    def basis(self, poses: np.ndarray) -> np.ndarray:
        """Q, an orthonormal basis of the geometric columns of these poses."""
        return self._basis(poses).q

    def pinv(self, poses: np.ndarray) -> np.ndarray:
        """G+, the pseudo-inverse of the geometric columns of these poses (kept within the
        budget of calib.diagnosis.basis, else made now)."""
        return self._basis(poses).pinv()

    def _basis(self, poses: np.ndarray) -> Basis:
        key = np.asarray(poses, bool).tobytes()
        if key not in self._cache:
            g, _ = self.rows(poses)
            self._cache[key] = make_basis(g, self._keeps_pinv(len(g)))
        return self._cache[key]

    def _keeps_pinv(self, rows: int) -> bool:
        """Whether the pseudo-inverse of a set of ``rows`` rows is kept (counted if so)."""
        size = 8 * rows * self.geo.shape[2]
        if self._pinv_bytes + size > PINV_BUDGET:
            return False
        self._pinv_bytes += size
        return True

    def fill(self, sets: list[np.ndarray], workers: int) -> None:
        """The bases and projected residuals of ``sets`` (pose masks) into the cache, each set
        a task: with ``workers`` > 1 made side by side in forked workers, which write the
        large arrays into shared memory (the arithmetic of :meth:`basis` and
        :meth:`projected_residual`, so the same numbers)."""
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
        sizes = [int(poses.sum()) * self.r.shape[1] for poses in todo]
        keeps = [self._keeps_pinv(n) for n in sizes]  # decided here, in the sets' order
        # per set: room for Q (at most p columns), G+ when it is kept, the projected residual
        slots = [
            (shared_array((n * p,)), shared_array((n * p if keep else 0,)), shared_array((n,)))
            for n, keep in zip(sizes, keeps, strict=True)
        ]

        def one(i: int) -> tuple:
            g, rt = self.rows(todo[i])
            b = make_basis(g, keeps[i])
            rp = rt - b.q @ (b.q.T @ rt)
            for slot, a in zip(slots[i], (b.q, b.kept_pinv, rp), strict=True):
                if a is not None:
                    slot[: a.size] = a.ravel(order="K")  # in its own memory order
            shapes = [None if a is None else (a.shape, _order(a)) for a in (b.q, b.kept_pinv)]
            # U itself only when Q lacks some of its columns (a rank-deficient geometry: rare)
            return shapes, b.u, b.vt, b.inv, b.scale

        for poses, slot, (shapes, u, vt, inv, scale) in zip(
            todo, slots, map_in_order(one, len(todo), workers), strict=True
        ):
            if vt is None:  # an empty basis (no rows or no columns): made here
                self._cache[poses.tobytes()] = make_basis(self.rows(poses)[0], False)
                self.projected_residual(poses)
                continue
            # views of the shared memory in the layout make_basis gives (column-major Q): a
            # BLAS product's order of sums, so its last bits, follow it
            q, kept = (
                None if sh is None else a[: int(np.prod(sh[0]))].reshape(sh[0], order=sh[1])
                for a, sh in zip(slot[:2], shapes, strict=True)
            )
            self._cache[poses.tobytes()] = Basis(q, u, vt, inv, scale, kept)
            self._cache[("rp", poses.tobytes())] = (self.residual_rows(poses), slot[2])


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
    q, gplus = prob.basis(poses), prob.pinv(poses)
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
