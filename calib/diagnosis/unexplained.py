"""Structure no physical candidate explains: rank correlations and a kernel correction.

When no candidate lowers the held-out error, the residual is still tested for structure:
Spearman rank correlation of each pose's residual size with tool position, tool orientation,
each actuator and the measurement order; and a non-parametric correction (Nadaraya-Watson
kernel smoothing of the residual vector over one group of pose variables, bandwidth by
leave-one-out on the training poses that carry it) is tried on held-out poses. If it lowers the
held-out error the answer is "unexplained: correlated with <group>", not a wrong effect and not
"none".
"""

from __future__ import annotations

import numpy as np

from calib.analysis.rank_structure import rank_correlations
from calib.analysis.spearman import spearman
from calib.diagnosis.context import Context
from calib.diagnosis.problem import Problem
from common.worker_processes import Progress, map_in_order, worker_count
from twin.rotations import rotvec_from_matrix

BANDWIDTHS = (0.15, 0.3, 0.6, 1.2, 2.5)


def features(ctx: Context) -> dict[str, np.ndarray]:
    """Groups of pose variables (N, d): where, how turned, which commands, when."""
    mean_r = ctx.tool_rotation.mean(axis=0)
    u, _, vt = np.linalg.svd(mean_r)
    mean_r = u @ vt
    turn = rotvec_from_matrix(ctx.tool_rotation @ mean_r.T)
    return {
        "tool position": ctx.targets.mean(axis=1),
        "tool orientation": np.atleast_2d(turn).reshape(len(turn), 3),
        "actuator commands": ctx.commands,
        "measurement order": ctx.time[:, None],
    }


def structure_detail(r: np.ndarray, keep: np.ndarray, ctx: Context) -> dict[str, dict[str, float]]:
    """Spearman rho and p of the per-pose residual size with every pose variable."""
    count = np.maximum(keep.sum(axis=1), 1)
    size = np.sqrt(np.sum(np.where(keep, r, 0.0) ** 2, axis=1) / count)
    f = features(ctx)
    probes = {}
    for i, c in enumerate("xyz"):
        probes[f"tool {c}"] = f["tool position"][:, i]
        probes[f"tool r{c}"] = f["tool orientation"][:, i]
    for i, n in enumerate(ctx.actuator_names):
        probes[n] = ctx.commands[:, i]
    probes["order"] = ctx.time
    return rank_correlations(size, probes)


# Nadaraya-Watson over at most this many training poses (evenly spaced through them): the
# smoother's cost is (poses evaluated) x (training poses), so a campaign of N poses costs
# N x 1,500 instead of N^2 (an 8,000-pose arm: 16 minutes and 9 GB before), and its bandwidth
# 1,500^2 (their leave-one-out); every campaign up to 1,500 poses uses all of them, as before
MAX_TRAINING_POSES = 1500
BLOCK = 512  # poses evaluated at once: memory BLOCK x training poses per array


def _squared_distances(a: np.ndarray, b: np.ndarray, out: np.ndarray, work: np.ndarray) -> None:
    """``out`` (n, m) = sum over the d coordinates of (a[:, None] - b[None]) ** 2, coordinate
    by coordinate into (n, m) arrays: the sum in the order a reduction over a last axis of
    fewer than 8 values adds them (the same numbers as ``np.sum(..., axis=2)`` of the
    (n, m, d) differences), without that array or its strided reduction. From 8 values on
    numpy sums pairwise: that sum itself, for the same numbers."""
    if a.shape[1] >= 8:
        np.sum((a[:, None, :] - b[None, :, :]) ** 2, axis=2, out=out)
        return
    out.fill(0.0)
    for k in range(a.shape[1]):
        np.subtract.outer(a[:, k], b[:, k], out=work)
        np.multiply(work, work, out=work)
        out += work


def _smooth_all(
    x_train: np.ndarray,
    e_train: np.ndarray,
    x_eval: np.ndarray,
    hs: tuple[float, ...],
    self_index: np.ndarray | None = None,
) -> list[np.ndarray]:
    """The kernel smoother of ``e_train`` (n, R) at ``x_eval`` for each bandwidth of ``hs``,
    the squared distances computed once for all of them, in blocks of evaluated poses.
    ``self_index`` (len(x_eval),): the training row each evaluated pose is (left out of its
    own smoothing), -1 for none."""
    out = [np.empty((len(x_eval), e_train.shape[1])) for _ in hs]
    d2 = np.empty((min(BLOCK, len(x_eval)), len(x_train)))
    diff, w = np.empty_like(d2), np.empty_like(d2)
    for lo in range(0, len(x_eval), BLOCK):
        hi = min(lo + BLOCK, len(x_eval))
        _squared_distances(x_eval[lo:hi], x_train, d2[: hi - lo], diff[: hi - lo])
        if self_index is not None:
            own = self_index[lo:hi]
            rows = np.flatnonzero(own >= 0)
            own = own[rows]
        half = d2[: hi - lo]
        np.multiply(half, -0.5, out=half)  # once for every bandwidth
        for j, h in enumerate(hs):
            w = w[: hi - lo]
            np.divide(half, h**2, out=w)  # exp(-0.5 d2 / h^2)
            np.exp(w, out=w)
            if self_index is not None:
                w[rows, own] = 0.0
            total = w.sum(axis=1, keepdims=True)
            total[total == 0] = 1.0
            out[j][lo:hi] = (w @ e_train) / total
    return out


def _training_subset(n: int) -> np.ndarray:
    """Indices of the training poses the smoother uses: all up to MAX_TRAINING_POSES, else
    that many evenly spaced through them (deterministic)."""
    if n <= MAX_TRAINING_POSES:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, MAX_TRAINING_POSES).round().astype(int))


def kernel_correction(prob: Problem, x: np.ndarray, train: np.ndarray, keep: np.ndarray):
    """Geometry refit on ``train`` and a kernel smoother of its residual over ``x``:
    returns a function (poses mask) -> corrected residual (n, R)."""
    gplus = prob.pinv(train)
    rt = prob.residual_rows(train)
    beta = gplus @ rt
    e_tr = (prob.r[train] - prob.geo[train] @ beta) * keep[train]
    mu, sd = x[train].mean(axis=0), x[train].std(axis=0)
    sd[sd == 0] = 1.0
    z = (x - mu) / sd
    zt = z[train] / np.sqrt(z.shape[1])
    sub = _training_subset(len(zt))
    z_sub, e_sub, keep_sub = zt[sub], e_tr[sub], keep[train][sub]
    # the bandwidth: leave-one-out over the poses that carry the smoother (each left out of
    # its own smoothing), against no correction; on a long campaign that is MAX_TRAINING_POSES
    # of them, its cost fixed, not another (training poses x MAX_TRAINING_POSES x bandwidths)
    best, best_h = np.sum(e_sub**2), None
    smoothed = _smooth_all(z_sub, e_sub, z_sub, BANDWIDTHS, np.arange(len(sub)))
    for h, fitted in zip(BANDWIDTHS, smoothed, strict=True):
        loo = e_sub - fitted * keep_sub
        sse = float(np.sum(loo**2))
        if sse < best:
            best, best_h = sse, h

    def corrected(poses: np.ndarray) -> np.ndarray:
        e = prob.r[poses] - prob.geo[poses] @ beta
        if best_h is None:
            return e
        z_eval = z[poses] / np.sqrt(z.shape[1])
        return e - _smooth_all(z_sub, e_sub, z_eval, (best_h,))[0] * keep[poses]

    return corrected, best_h


def kernel_heldout(
    prob: Problem, groups: dict[str, np.ndarray], folds: dict[str, np.ndarray], keep: np.ndarray
) -> dict[str, dict[str, np.ndarray]]:
    """Per-pose held-out SSE of geometry + the kernel correction over each group's pose
    variables (``groups``: name -> (N, d)), per fold scheme. Every (group, scheme, fold) is
    its own fit, evaluated side by side in worker processes on a long run (the numbers of
    one process, bit for bit: common.worker_processes)."""
    tasks = [
        (group, scheme, f)
        for group in groups
        for scheme, labels in folds.items()
        for f in range(int(labels.max()) + 1)
    ]

    def one(i: int) -> np.ndarray:
        group, scheme, f = tasks[i]
        test = folds[scheme] == f
        corrected, _ = kernel_correction(prob, groups[group], ~test, keep)
        return np.sum(corrected(test) ** 2, axis=1)

    out = {g: {s: np.zeros(len(labels)) for s, labels in folds.items()} for g in groups}
    workers = worker_count(prob.r.size, len(tasks))
    progress = Progress("kernel corrections", len(tasks), workers)
    for (group, scheme, f), sse in zip(tasks, map_in_order(one, len(tasks), workers), strict=True):
        out[group][scheme][folds[scheme] == f] = sse
        progress.step(group)
    return out


def residual_structure(
    r: np.ndarray,
    targets: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    keep: np.ndarray | None = None,
) -> dict[str, float]:
    """Spearman rank correlation of each pose's residual size with where and when it was
    measured: tool position x, y, z (space), mean actuator value (actuator coordinates) and
    measurement order (time). Values near 0 mean no structure along that direction.

    ``keep`` (same shape as ``r``) marks the rows to use; a pose with none is left out."""
    keep = np.ones(r.shape, dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    count = keep.sum(axis=1)
    some = count > 0
    size = np.sqrt(np.sum(np.where(keep, r, 0.0) ** 2, axis=1)[some] / count[some])
    centre = targets.mean(axis=1)[some]
    commands = np.asarray(commands)[some]
    order = np.asarray(order)[some]
    probes = {
        "x": centre[:, 0],
        "y": centre[:, 1],
        "z": centre[:, 2],
        "mean_actuator": commands.mean(axis=1),
        "order": np.asarray(order, dtype=float),
    }
    out = {}
    for name, v in probes.items():
        rho = spearman(size, v)[0] if np.ptp(v) > 0 else 0.0
        out[name] = float(np.nan_to_num(rho))
    return out
