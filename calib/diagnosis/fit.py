"""Fitting candidates beside the geometry, and judging them on poses that did not fit them.

The residual r (N poses, R rows) of the geometric calibration is fitted, on a set of training
poses, by a geometric correction (the identified parameters' columns G) plus the candidates'
columns X: r ~ G beta + X theta, linearised at the geometric estimate. Sign constraints
(a play, a compliance cannot be negative) are bounds of the fit.

Nested cross-validation: in every outer training set a candidate's shape (pitch, time
constant, harmonic, payload) is scanned on a grid by least squares, the best local minima are
refined (bounded Brent searches side by side, calib.diagnosis.bounded_search), and the finalists are
compared by an inner cross-validation of that training set only; the outer held-out poses
never take part in the choice. Outer folds are contiguous
blocks of the measurement order (a drift must predict *later* poses) and random.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.diagnosis.basis import RCOND
from calib.diagnosis.candidate import Candidate
from calib.diagnosis.context import Context
from calib.diagnosis.problem import Fit, Problem, _flat, fit, heldout_sse
from calib.diagnosis.shape_scan import choose_shape, inner_folds, rss_over_grid


def lower_bounds(cands: list[Candidate], xs: list[np.ndarray]) -> np.ndarray | None:
    lows = []
    for c, x in zip(cands, xs, strict=True):
        nn = c.nonnegative or (False,) * x.shape[2]
        lows.append(np.where(np.asarray(nn, bool), 0.0, -np.inf))
    low = np.concatenate(lows) if lows else np.zeros(0)
    return low if np.any(np.isfinite(low)) else None


@dataclass(frozen=True)
class Evaluation:
    """One model (a set of candidates) judged on held-out poses."""

    names: tuple[str, ...]
    heldout: dict[str, np.ndarray]  # scheme -> per-pose held-out SSE (N,)
    fold_shapes: dict[str, list[tuple[float, ...]]]  # scheme -> per fold, per candidate
    shapes: tuple[float, ...]  # from all poses, per candidate
    fit: Fit  # on all poses
    sizes: tuple[int, ...]  # parameters per candidate
    n_rows: int

    def heldout_rms_mm(self, scheme: str | None = None) -> float:
        if scheme is None:
            return (
                float(np.sqrt(np.mean([np.sum(v) for v in self.heldout.values()]) / self.n_rows))
                * 1e3
            )
        return float(np.sqrt(np.sum(self.heldout[scheme]) / self.n_rows)) * 1e3


def evaluate(
    prob: Problem,
    ctx: Context,
    folds: dict[str, np.ndarray],
    cands: list[Candidate],
    previous: Evaluation | None,
    n_rows: int,
) -> Evaluation:
    """Nested CV of geometry + ``cands``; the shapes of the candidates already in
    ``previous`` are kept per fold, only the last candidate's shape is chosen here."""
    n = ctx.n_poses
    new = cands[-1] if cands else None
    heldout, fold_shapes = {}, {}
    for scheme, labels in folds.items():
        sse = np.zeros(n)
        shapes_s = []
        for f in range(int(labels.max()) + 1):
            train, test = labels != f, labels == f
            old = previous.fold_shapes[scheme][f] if previous is not None else ()
            fixed = [c.design(ctx, s) for c, s in zip(cands[:-1], old, strict=True)]
            shp = (*old, choose_shape(prob, fixed, new, ctx, train)) if new else ()
            xs = [c.design(ctx, s) for c, s in zip(cands, shp, strict=True)]
            ft = fit(prob, xs, train, lower_bounds(cands, xs))
            sse[test] = heldout_sse(prob, xs, ft, test)
            shapes_s.append(shp)
        heldout[scheme], fold_shapes[scheme] = sse, shapes_s
    everything = np.ones(n, bool)
    old = previous.shapes if previous is not None else ()
    fixed = [c.design(ctx, s) for c, s in zip(cands[:-1], old, strict=True)]
    shapes = (*old, choose_shape(prob, fixed, new, ctx, everything)) if new else ()
    xs = [c.design(ctx, s) for c, s in zip(cands, shapes, strict=True)]
    full = fit(prob, xs, everything, lower_bounds(cands, xs))
    return Evaluation(
        names=tuple(c.name for c in cands),
        heldout=heldout,
        fold_shapes=fold_shapes,
        shapes=shapes,
        fit=full,
        sizes=tuple(x.shape[2] for x in xs),
        n_rows=n_rows,
    )


def shared_bases(
    prob: Problem, ctx: Context, folds: dict[str, np.ndarray], workers: int = 1
) -> None:
    """The projection bases and residuals every candidate's :func:`evaluate` reads, into
    ``prob``'s cache: of each outer training set, all poses, and their inner folds' training
    sets (the same numbers as when a candidate's evaluation first asks for them), made by
    ``workers`` processes."""
    outer = [labels != f for labels in folds.values() for f in range(int(labels.max()) + 1)]
    sets = []
    for train in [*outer, np.ones(ctx.n_poses, bool)]:
        sets += [train, *(inner for inner, _ in inner_folds(ctx, train))]
    prob.fill(sets, workers)


@dataclass(frozen=True)
class Uncertainty:
    theta: np.ndarray  # unconstrained estimate, SI
    std: np.ndarray  # its standard errors, SI
    shape_std: tuple[float, ...]  # per candidate (NaN when no shape or not defined)
    sigma2: float  # residual variance per row
    cov: np.ndarray | None = None  # of theta, SI (NaN rows and columns where not seen)


def uncertainty(prob: Problem, ctx: Context, cands: list[Candidate], ev: Evaluation) -> Uncertainty:
    """Unconstrained estimate and standard errors at the chosen shapes (all poses); the
    shape's standard error from the curvature of the profile RSS."""
    n = ctx.n_poses
    everything = np.ones(n, bool)
    xs = [c.design(ctx, s) for c, s in zip(cands, ev.shapes, strict=True)]
    q = prob.basis(everything)
    rt = prob.residual_rows(everything)
    xt = _flat(xs, everything).reshape(len(rt), -1)
    xp = xt - q @ (q.T @ xt)
    rp = rt - q @ (q.T @ rt)
    norms = np.linalg.norm(xp, axis=0)
    live = norms > RCOND * max(float(norms.max(initial=0.0)), 1e-300)
    theta = np.zeros(xp.shape[1])
    theta[live] = np.linalg.lstsq(xp[:, live], rp, rcond=RCOND)[0]
    resid = rp - xp @ theta
    dof = max(ev.n_rows - q.shape[1] - xt.shape[1] - sum(c.shaped for c in cands), 1)
    sigma2 = float(resid @ resid) / dof
    std = np.full(xp.shape[1], np.nan)  # a parameter the data does not see: no std error
    full_cov = np.full((xp.shape[1], xp.shape[1]), np.nan)
    if np.any(live):
        a = xp[:, live] / norms[live]
        cov = sigma2 * np.linalg.pinv(a.T @ a, rcond=RCOND) / np.outer(norms[live], norms[live])
        std[live] = np.sqrt(np.clip(np.diag(cov), 0, None))
        full_cov[np.ix_(live, live)] = cov
    shape_std = []
    for i, (c, s) in enumerate(zip(cands, ev.shapes, strict=True)):
        if not c.shaped or not np.isfinite(s) or c.shape_name == "harmonic":
            shape_std.append(float("nan"))
            continue
        others = [x for j, x in enumerate(xs) if j != i]
        u = np.log(s) if c.shape_log else s
        h = 1e-3 * (1.0 if c.shape_log else abs(s) or 1.0)

        def rss(v: float, c=c, others=others) -> float:
            val = float(np.exp(v)) if c.shape_log else v
            return float(rss_over_grid(prob, others, c, ctx, [val], everything)[0])

        curv = (rss(u + h) - 2 * rss(u) + rss(u - h)) / h**2
        sd = float(np.sqrt(2 * sigma2 / curv)) if curv > 0 else float("nan")
        shape_std.append(s * sd if c.shape_log else sd)
    return Uncertainty(theta, std, tuple(shape_std), sigma2, full_cov)


# a scaled singular value below this fraction of the largest is zero: identify's rank rule
# (calib.analysis.identifiability.RANK_RTOL), so that what identify --with would fix as
# redundant is what the diagnosis does not print a value for
DETERMINED_RTOL = 1e-9


def undetermined(prob: Problem, ctx: Context, cands: list[Candidate], ev: Evaluation) -> np.ndarray:
    """Per effect parameter (in the order of ``ev.fit.theta``), whether the data leave it
    undetermined: its column (at the chosen shapes, all poses) lies in the span of the
    geometry's columns and the other effect parameters' (dropping it does not lower the
    rank of the unit-scaled columns). A parameter without a column (the data do not see
    it) is not counted here: it keeps value 0 without a standard error."""
    everything = np.ones(ctx.n_poses, bool)
    xs = [c.design(ctx, s) for c, s in zip(cands, ev.shapes, strict=True)]
    q = prob.basis(everything)
    xt = _flat(xs, everything).reshape(q.shape[0], -1)
    norms = np.linalg.norm(xt, axis=0)
    out = np.zeros(len(norms), dtype=bool)
    live = np.flatnonzero(norms > 0)
    if live.size == 0:
        return out
    cols = np.hstack([q, xt[:, live] / norms[live]])
    r = np.linalg.qr(cols, mode="r")  # the same singular values in as many rows as columns

    def rank(a: np.ndarray) -> int:
        s = np.linalg.svd(a, compute_uv=False)
        return int(np.sum(s > DETERMINED_RTOL * s[0])) if s.size and s[0] > 0 else 0

    full = rank(r)
    for i, j in enumerate(live):
        out[j] = rank(np.delete(r, q.shape[1] + i, axis=1)) == full
    return out
