"""Which feasible poses to measure: the most informative for the calibration, and a test set
that covers the workspace.

Calibration poses maximise an observability index of the identification Jacobian at the
nominal values (calib.fit.CalibrationModel.jacobian): by default the D-optimal exchange
(calib.analysis.pose_selection.exchange, from a seeded random start), or the second paper's
greedy selection of the condition number (``paper_selection``). Parameters no pose can
identify (a DH arm's parallel joints, a zero and a length along one axis) make every index
undefined, so the blocks are first projected onto the directions the whole candidate pool
identifies (the right singular vectors of its column-scaled Jacobian above the rank
tolerance): the index of what can be identified. Test poses are a farthest-point cover of the
targets' positions (every target's, so that orientation counts on a machine with several)
among the poses left, started next to their centroid."""

from __future__ import annotations

import numpy as np

from calib.analysis.identifiability import RANK_RTOL, column_scale
from calib.analysis.pose_selection import exchange, paper_selection
from calib.exceptions import IdentifiabilityError
from calib.fit.model import CalibrationModel
from twin.kinematics.structure import one_blas_thread

CRITERIA = ("d_optimal", "paper")


def pose_blocks(model: CalibrationModel, commands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-pose Jacobian blocks (C, 3T, r) projected onto the r directions the candidates
    identify, and the nominal target positions (C, T, 3) (m)."""
    x0 = np.zeros(model.n_parameters)
    pred = model.predict(x0, commands)
    jac = model.jacobian(x0, pred)
    with one_blas_thread():
        scale = column_scale(jac)
        _, s, vt = np.linalg.svd(jac / scale, full_matrices=False)
    rank = int(np.sum(s > RANK_RTOL * s[0])) if s.size else 0
    if rank == 0:
        raise IdentifiabilityError("the candidate poses identify no parameter")
    blocks = ((jac / scale) @ vt[:rank].T).reshape(len(commands), -1, rank)
    return blocks, pred.targets


def choose(
    blocks: np.ndarray, n: int, criterion: str, rng: np.random.Generator
) -> tuple[list[int], float]:
    """``n`` candidates (indices into ``blocks``) and the index value they reach (log det of
    the scaled information for d_optimal, the condition number for paper)."""
    count, rows, rank = blocks.shape
    if criterion not in CRITERIA:
        raise ValueError(f"unknown criterion '{criterion}'; known: {CRITERIA}")
    if n > count:
        raise IdentifiabilityError(f"asked for {n} poses but only {count} candidates are feasible")
    if n * rows < rank:
        raise IdentifiabilityError(
            f"{n} poses give {n * rows} equations for the {rank} directions the candidates "
            f"identify: plan at least {-(-rank // rows)} poses"
        )
    stack = list(blocks)
    if criterion == "paper":
        start = min(n, max(9, -(-rank // rows) + 2))
        best, _ = paper_selection(stack, rng, n_starts=5, n_initial=start, until=n)
        return sorted(best.indices), best.final
    start = sorted(rng.choice(count, size=n, replace=False).tolist())
    chosen, value = exchange(stack, start, name="d_optimality")
    return sorted(chosen), value


def cover(points: np.ndarray, n: int, exclude: list[int] | np.ndarray) -> list[int]:
    """``n`` indices of ``points`` (C, d), none of ``exclude``: each the farthest from those
    taken, the first the nearest to the centroid of the available."""
    points = np.asarray(points, dtype=float).reshape(len(points), -1)
    free = np.setdiff1d(np.arange(len(points)), np.asarray(exclude, dtype=int))
    if n > len(free):
        raise IdentifiabilityError(
            f"{n} test poses asked but only {len(free)} feasible poses are left after the "
            "calibration poses"
        )
    if n == 0:
        return []
    pts = points[free]
    first = int(np.argmin(np.linalg.norm(pts - pts.mean(axis=0), axis=1)))
    taken = [first]
    dist = np.linalg.norm(pts - pts[first], axis=1)
    while len(taken) < n:
        k = int(np.argmax(dist))
        taken.append(k)
        dist = np.minimum(dist, np.linalg.norm(pts - pts[k], axis=1))
    return sorted(int(free[k]) for k in taken)
