"""A candidate's shape (pitch, time constant, harmonic, payload) chosen on a training set: a
least-squares scan over a grid, the best local minima refined (bounded Brent searches side by
side, calib.diagnosis.bounded_search), the finalists compared by an inner cross-validation of
that training set only."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from calib.diagnosis.basis import RCOND, _orth
from calib.diagnosis.bounded_search import minimise_together
from calib.diagnosis.candidate import NO_SHAPE, Candidate, PoseRows
from calib.diagnosis.context import Context
from calib.diagnosis.problem import Problem, _flat, _solve, _sse, fold_labels

N_FINALISTS = 3
INNER_FOLDS = 4
REFINE_XTOL = 1e-2  # a shape refined to 1 % of the span between its grid neighbours
GRID_CHUNK = 64  # shapes whose columns are formed at once in a grid scan
# an actuator-level candidate's scan through its offsets (products over poses, not rows) from
# this many shapes on; smaller grids keep the columns themselves, whose X^T X - X^T Q Q^T X
# rounds as the per-shape reference does (the factored form can differ by ~1e-11 relative
# where the columns lie almost in the geometry's span)
FACTORED_MIN_SHAPES = 64


@dataclass(frozen=True)
class GridDesign:
    """A candidate's columns at every shape of a grid, laid out for scans over many training
    sets: ``x`` (N*R, S*k), the shapes side by side, and each pose's Gram matrices X_n^T X_n
    ``gram`` (N, S*k*k)."""

    x: np.ndarray
    gram: np.ndarray
    n_shapes: int
    k: int


def grid_designs(prob: Problem, cand: Candidate, ctx: Context, grid) -> GridDesign:
    """Columns of the candidate at every shape of ``grid``, cached per grid (built in chunks
    of shapes: no temporary of the whole grid's size besides the result)."""
    key = (cand.name, id(ctx), np.asarray(grid, float).tobytes())
    if key not in prob._cache:
        grid = np.asarray(grid, dtype=float)
        x = gram = None
        for lo in range(0, len(grid), GRID_CHUNK):
            xc = cand.designs(ctx, grid[lo : lo + GRID_CHUNK])  # (N, s, R, k)
            if x is None:
                n, _, r, k = xc.shape
                x = np.empty((n, r, len(grid), k))
                gram = np.empty((n, len(grid), k, k))
            x[:, :, lo : lo + GRID_CHUNK] = xc.transpose(0, 2, 1, 3)
            gram[:, lo : lo + GRID_CHUNK] = np.matmul(xc.transpose(0, 1, 3, 2), xc)
        assert x is not None and gram is not None
        prob._cache[key] = GridDesign(x.reshape(n * r, -1), gram.reshape(n, -1), len(grid), k)
    return prob._cache[key]


@dataclass(frozen=True)
class GridOffsets:
    """An actuator-level candidate's grid kept as its offsets: X(s) = J_act O(s), O nonzero
    only at the (actuator ``act[p]``, parameter ``col[p]``) pairs p, ``o`` (P, N, S); ``j``
    (N, R, A) is J_act with the rejected rows zeroed. A training set's normal equations then
    cost products over the poses, not over every residual row."""

    o: np.ndarray
    act: np.ndarray
    col: np.ndarray
    j: np.ndarray
    k: int


def grid_offsets(prob: Problem, cand: Candidate, ctx: Context, grid) -> GridOffsets:
    """The offsets of an actuator-level candidate at every shape of ``grid``, cached."""
    key = ("offsets", cand.name, id(ctx), np.asarray(grid, float).tobytes())
    if key not in prob._cache:
        assert cand.offsets is not None and ctx.j_act is not None
        grid = np.asarray(grid, dtype=float)
        if cand.offset_pairs is not None:
            o, act, col, k = _pairs_used(cand.offset_pairs(ctx, grid))
        else:
            chunks = []
            for lo in range(0, len(grid), GRID_CHUNK):
                chunks.append(cand.offsets_at(ctx, grid[lo : lo + GRID_CHUNK]))  # (N, s, A, k)
            used = np.zeros(chunks[0].shape[2:], bool)
            for oc in chunks:
                used |= np.any(oc != 0, axis=(0, 1))
            act, col = np.nonzero(used)
            o = np.concatenate([oc[:, :, act, col] for oc in chunks], axis=1)  # (N, S, P)
            k = used.shape[1]
        j = ctx.j_act if ctx.rows is None else ctx.j_act * ctx.rows[:, :, None]
        prob._cache[key] = GridOffsets(np.ascontiguousarray(o.transpose(2, 0, 1)), act, col, j, k)
    return prob._cache[key]


def _pairs_used(pairs) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """A candidate's offset pairs as the dense offsets give them: the pairs with a nonzero
    value, ordered by actuator then parameter (``np.nonzero`` of the (A, k) pattern)."""
    o, act, col, k = pairs
    used = np.any(o != 0, axis=(0, 1))
    order = np.lexsort((col[used], act[used]))
    keep = np.flatnonzero(used)[order]
    return o[:, :, keep], act[keep], col[keep], k


@dataclass(frozen=True)
class Projection:
    """The training residual with the geometry and the ``fixed`` columns projected out."""

    q: np.ndarray  # orthonormal basis of the geometric and fixed columns of the poses
    rp: np.ndarray  # the residual rows orthogonal to q
    base: float  # |rp|^2
    m: int  # rows


def projection(prob: Problem, fixed: list[np.ndarray], poses: np.ndarray) -> Projection:
    """What :func:`rss_over_grid` needs of the poses and ``fixed``, whatever the shape: one
    computation serves the grid scan and every refinement of one candidate's shape."""
    q0 = prob.basis(poses)
    rt, rp = prob.projected_residual(poses)
    if fixed:
        xf = _flat(fixed, poses).reshape(len(rt), -1)
        q = _orth(np.hstack([q0, xf - q0 @ (q0.T @ xf)]))
        rp = rt - q @ (q.T @ rt)
    return Projection(q0 if not fixed else q, rp, float(rp @ rp), len(rt))


def rss_over_grid(
    prob: Problem,
    fixed: list[np.ndarray],
    cand: Candidate,
    ctx: Context,
    grid,
    poses,
    cache: bool = False,
    proj: Projection | None = None,
) -> np.ndarray:
    """Training RSS of geometry + ``fixed`` + candidate at each shape (unconstrained);
    ``proj``: :func:`projection` of the same ``fixed`` and poses, if already computed.
    ``cache``: the grid's columns computed once for every training set (a grid scan)."""
    proj = projection(prob, fixed, poses) if proj is None else proj
    if cache and cand.offsets is not None and len(grid) >= FACTORED_MIN_SHAPES:
        ata, atb = _normal_equations_offsets(grid_offsets(prob, cand, ctx, grid), proj, poses)
    elif cache:
        ata, atb = _normal_equations_cached(grid_designs(prob, cand, ctx, grid), proj, poses)
    else:
        ata, atb = _normal_equations(cand, ctx, grid, poses, proj)
    out = np.empty(len(grid))
    for lo in range(0, len(grid), 64):
        out[lo : lo + 64] = proj.base - _explained(ata[lo : lo + 64], atb[lo : lo + 64])
    return out


def rss_at(
    cand: Candidate, ctx: Context, shapes: list[float], at: PoseRows, proj: Projection
) -> list[float]:
    """``rss_over_grid(..., [shape], poses, proj=proj)[0]`` at each of ``shapes`` for the
    poses of ``at``: the same arithmetic shape by shape (a matrix product or solve of a stack
    is the product or solve of each of its items), one stack for the points of the
    refinements running side by side."""
    x = np.stack([cand.design_at(ctx, float(v), at) for v in shapes])
    ata, atb = _normal_equations_of(x.reshape(len(shapes), proj.m, -1), proj)
    return [float(proj.base - e) for e in _explained(ata, atb, each_alone=True)]


def _normal_equations(
    cand: Candidate, ctx: Context, grid, poses: np.ndarray, proj: Projection
) -> tuple[np.ndarray, np.ndarray]:
    """X^T (I - Q Q^T) X (S, k, k) and X^T rp (S, k) at each shape, from the designs."""
    at = PoseRows.of(ctx, poses)
    x = np.stack([cand.design_at(ctx, float(v), at) for v in grid])
    return _normal_equations_of(x.reshape(len(grid), proj.m, -1), proj)


def _normal_equations_of(x: np.ndarray, proj: Projection) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_normal_equations` from the columns ``x`` (S, m, k) of the training rows."""
    qx = np.matmul(proj.q.T, x)  # (S, r, k)
    ata = np.matmul(x.transpose(0, 2, 1), x) - np.matmul(qx.transpose(0, 2, 1), qx)
    atb = np.matmul(x.transpose(0, 2, 1), proj.rp)  # rp is orthogonal to q already
    return ata, atb


def _normal_equations_cached(
    design: GridDesign, proj: Projection, poses: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """As :func:`_normal_equations` from the grid's cached columns: Q and rp padded with zero
    rows for the poses outside the training set, one product for all shapes, X^T X as the sum
    of the training poses' Gram matrices."""
    s, k = design.n_shapes, design.k
    q, rp = _padded(proj, poses)
    qx = (design.x.T @ q.reshape(-1, q.shape[2])).reshape(s, k, -1)  # (S, k, r)
    xtx = (np.asarray(poses, float) @ design.gram).reshape(s, k, k)
    ata = xtx - np.matmul(qx, qx.transpose(0, 2, 1))
    atb = (rp.reshape(-1) @ design.x).reshape(s, k)
    return ata, atb


def _padded(proj: Projection, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Q (N, R, r) and rp (N, R) of the projection, zero at the poses outside the set."""
    n = len(poses)
    q = np.zeros((n, proj.m // int(np.sum(poses)), proj.q.shape[1]))
    q[poses] = proj.q.reshape(-1, q.shape[1], q.shape[2])
    rp = np.zeros(q.shape[:2])
    rp[poses] = proj.rp.reshape(-1, q.shape[1])
    return q, rp


def _normal_equations_offsets(
    g: GridOffsets, proj: Projection, poses: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """As :func:`_normal_equations` for X(s) = J_act O(s): with W_n = Q_n^T J_n, M_n = J_n^T J_n
    and c_n = J_n^T rp_n per pose, Q^T X, X^T X and X^T rp are sums over the training poses
    of W_n O_n, O_n^T M_n O_n and O_n^T c_n."""
    q, rp = _padded(proj, poses)
    w = np.matmul(q.transpose(0, 2, 1), g.j)  # (N, r, A)
    c = np.einsum("nr,nra->na", rp, g.j)  # (N, A)
    m = np.matmul(g.j.transpose(0, 2, 1), g.j) * np.asarray(poses, float)[:, None, None]
    pick = np.zeros((g.k, len(g.act)))  # parameter <- pair
    pick[g.col, np.arange(len(g.act))] = 1.0
    # every parameter from exactly one pair (diagonal offsets): the sums over pairs below
    # have one term, so taking that term is the same number
    sel = np.argsort(g.col) if np.array_equal(np.sort(g.col), np.arange(g.k)) else None
    qx = np.matmul(w[:, :, g.act].transpose(2, 1, 0), g.o)  # (P, r, S)
    qx = qx[sel] if sel is not None else np.tensordot(pick, qx, axes=1)  # (k, r, S)
    n_pairs = len(g.act)
    gram = np.empty((n_pairs, n_pairs, g.o.shape[2]))
    for a in range(n_pairs):
        for b in range(a, n_pairs):
            gram[a, b] = gram[b, a] = (g.o[a] * g.o[b]).T @ m[:, g.act[a], g.act[b]]
    if sel is not None:
        xtx = gram[sel][:, sel].transpose(2, 0, 1)
    else:
        xtx = np.einsum("ip,pqs,jq->sij", pick, gram, pick)
    qxs = qx.transpose(2, 0, 1)  # (S, k, r)
    ata = xtx - np.matmul(qxs, qxs.transpose(0, 2, 1))
    cx = np.matmul(c[:, g.act].T[:, None, :], g.o)[:, 0, :]  # (P, S)
    atb = (cx[sel] if sel is not None else pick @ cx).T  # (S, k)
    return ata, atb


@functools.cache
def _ridge(k: int) -> np.ndarray:
    """The ridge added to the normalised normal equations (1, k, k)."""
    ridge = RCOND * np.eye(k)[None] * 1e2
    ridge.flags.writeable = False
    return ridge


def _explained(ata: np.ndarray, atb: np.ndarray, each_alone: bool = False) -> np.ndarray:
    """b^T A^-1 b at each shape, on the column-normalised normal equations. A singular
    system makes the whole stack use the pseudo-inverse; ``each_alone``: only that shape
    (each value then what the shape alone gives)."""
    d = np.sqrt(np.maximum(np.einsum("skk->sk", ata), 0.0))
    d[d < 1e-300] = 1.0
    a_n = ata / d[:, :, None] / d[:, None, :]
    b_n = atb / d
    a_n = a_n + _ridge(a_n.shape[1])
    try:
        sol = np.linalg.solve(a_n, b_n[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        if each_alone and len(ata) > 1:
            return np.concatenate(
                [_explained(ata[i : i + 1], atb[i : i + 1]) for i in range(len(ata))]
            )
        sol = np.einsum("sij,sj->si", np.linalg.pinv(a_n), b_n)
    return np.einsum("sk,sk->s", b_n, sol)


def _interval(cand: Candidate, grid: np.ndarray, i: int) -> tuple[float, float] | None:
    """Where the shape at grid index ``i`` is refined: between its grid neighbours (their
    logarithms for a log-scaled shape); None: the grid value stays."""
    s = float(grid[i])
    if cand.shape_name == "harmonic" or not np.isfinite(s) or len(grid) < 3:
        return None
    lo, hi = float(grid[max(i - 1, 0)]), float(grid[min(i + 1, len(grid) - 1)])
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return None
    lo, hi = min(lo, hi), max(lo, hi)
    if cand.shape_log and lo <= 0:
        return None
    return (np.log(lo), np.log(hi)) if cand.shape_log else (lo, hi)


def _refine(
    cand: Candidate,
    ctx: Context,
    grid: np.ndarray,
    minima: list[int],
    poses: np.ndarray,
    proj: Projection,
) -> list[float]:
    """Refine the shape of each grid index in ``minima`` between its grid neighbours: a
    bounded Brent search per index (scipy's, step for step: calib.diagnosis.bounded_search), the
    searches side by side so that their points are evaluated together."""
    spans = [_interval(cand, grid, i) for i in minima]
    todo = [span for span in spans if span is not None]
    at = PoseRows.of(ctx, poses)

    def cost(us: list[float]) -> list[float]:
        return rss_at(cand, ctx, [float(np.exp(u)) if cand.shape_log else u for u in us], at, proj)

    found = iter(minimise_together(cost, todo, [REFINE_XTOL * abs(b - a) + 1e-15 for a, b in todo]))
    out = []
    for i, span in zip(minima, spans, strict=True):
        if span is None:
            out.append(float(grid[i]))
        else:
            u = next(found)
            out.append(float(np.exp(u)) if cand.shape_log else float(u))
    return out


def choose_shape(
    prob: Problem, fixed: list[np.ndarray], cand: Candidate, ctx: Context, poses: np.ndarray
) -> float:
    """The candidate's shape from these poses only: grid scan, refined finalists, inner CV."""
    if not cand.shaped:
        return NO_SHAPE
    grid = np.asarray(cand.grid(ctx), dtype=float)
    proj = projection(prob, fixed, poses)
    rss = rss_over_grid(prob, fixed, cand, ctx, grid, poses, cache=True, proj=proj)
    inner = np.ones(len(rss), bool)
    inner[1:-1] = (rss[1:-1] <= rss[:-2]) & (rss[1:-1] <= rss[2:])
    minima = [i for i in np.argsort(rss) if inner[i]][:N_FINALISTS]
    finalists = _refine(cand, ctx, grid, minima, poses, proj)
    if len(finalists) == 1:
        return finalists[0]
    scores = _inner_cv(prob, fixed, [cand.design(ctx, s) for s in finalists], ctx, poses)
    return finalists[int(np.argmin(scores))]


def inner_folds(ctx: Context, poses: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The (training, held-out) pose masks of the inner cross-validation of ``poses``."""
    idx = np.flatnonzero(poses)
    labels = fold_labels(ctx.time[idx], INNER_FOLDS, "random", seed=1)
    out = []
    for f in range(INNER_FOLDS):
        train = np.zeros_like(poses)
        train[idx[labels != f]] = True
        test = np.zeros_like(poses)
        test[idx[labels == f]] = True
        out.append((train, test))
    return out


def _inner_cv(
    prob: Problem, fixed: list[np.ndarray], xs: list[np.ndarray], ctx: Context, poses: np.ndarray
) -> list[float]:
    """Held-out SSE of geometry + ``fixed`` + each of the columns ``xs`` (one candidate at
    its finalist shapes) by an inner cross-validation of ``poses``: per finalist, the sum over
    the folds of :func:`heldout_sse` after :func:`fit`, with what does not depend on the
    finalist (the fold's basis, residual and fixed columns) taken once per fold."""
    scores = [0.0] * len(xs)
    for train, test in inner_folds(ctx, poses):
        q, gplus = prob.basis(train), prob.pinv(train)
        rt, rp = prob.projected_residual(train)
        r_test, geo_test = prob.r[test], prob.geo[test]
        fixed_train = [x[train] for x in fixed]
        fixed_test = [x[test] for x in fixed]
        for i, x in enumerate(xs):
            xt = np.concatenate([*fixed_train, x[train]], axis=2).reshape(len(rt), -1)
            ft = _solve(q, gplus, rt, rp, xt)
            xv = np.concatenate([*fixed_test, x[test]], axis=2)
            scores[i] += float(np.sum(_sse(r_test, geo_test, xv, ft)))
    return scores
