"""Measurement design: which poses to measure, and how many.

Every method works on per-pose blocks of the identification Jacobian (rows of one pose) and an
observability index of their stack (calib.analysis.observability_indices, column-scaled):

* ``greedy``: the second paper's one-by-one algorithm (its Fig. 9): from a starting set, add
  the candidate that most improves the index, one pose at a time, up to a count;
* ``paper_selection``: that greedy run from many random starting sets, keeping the best;
* ``exchange``: a DETMAX-style exchange (Mitchell 1974) at a fixed count: swap a selected pose
  for a candidate whenever the swap improves the index, until no swap does.
Ties (values within ``TIE_RTOL`` of each other, relative: round-off is no preference) are
broken by the lower candidate index, and a swap must gain more than that, so results do not
depend on the BLAS kernel. The blocks must all have the same shape (k, n); each step
evaluates every candidate at once (calib.analysis.observability_indices.index_with_each).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.analysis.observability_indices import MAXIMISE, better, index_with_each, observability
from calib.exceptions import IdentifiabilityError

TIE_RTOL = 1e-8  # index values this close (relative) are equal: the lower index wins


@dataclass(frozen=True)
class Selection:
    indices: list[int]  # selected candidates, in the order they were added
    index_by_count: list[float]  # index after each addition (count = len(start) + k)
    start_count: int
    index_name: str

    @property
    def final(self) -> float:
        return self.index_by_count[-1]


def _value(blocks: list[np.ndarray], chosen: list[int], name: str) -> float:
    return observability(np.vstack([blocks[i] for i in chosen]), name, allow_deficient=True)


def _stack(blocks: list[np.ndarray] | np.ndarray) -> np.ndarray:
    stack = np.asarray(blocks, dtype=float)
    if stack.ndim != 3:
        raise ValueError("pose blocks must all have the same shape (rows, parameters)")
    return stack


def _margin(value: float) -> float:
    return TIE_RTOL * abs(value) if np.isfinite(value) else 0.0


def _gains(name: str, a: float, b: float) -> bool:
    """Is ``a`` better than ``b`` by more than round-off?"""
    return bool(a > b + _margin(b) if MAXIMISE[name] else a < b - _margin(b))


def _pick(values: np.ndarray, name: str) -> int:
    """Position of the best value; among values within round-off of it, the first."""
    best = float(np.max(values) if MAXIMISE[name] else np.min(values))
    if not np.isfinite(best):
        return int(np.flatnonzero(values == best)[0])
    close = np.abs(values - best) <= _margin(best)
    return int(np.flatnonzero(close)[0])


def greedy(
    blocks: list[np.ndarray], start: list[int], until: int, name: str = "condition"
) -> Selection:
    """Add, one at a time, the candidate whose addition gives the best index."""
    if until > len(blocks):
        raise IdentifiabilityError(
            f"asked for {until} poses from {len(blocks)} candidates: too few candidates"
        )
    stack = _stack(blocks)
    chosen = list(start)
    curve = [_value(blocks, chosen, name)]
    while len(chosen) < until:
        rest = [i for i in range(len(stack)) if i not in chosen]
        values = index_with_each(np.vstack(stack[chosen]), stack[rest], name)
        k = _pick(values, name)
        chosen.append(rest[k])
        curve.append(float(values[k]))
    return Selection(chosen, curve, len(start), name)


def paper_selection(
    blocks: list[np.ndarray],
    rng: np.random.Generator,
    n_starts: int = 30,
    n_initial: int = 9,
    until: int = 40,
    name: str = "condition",
) -> tuple[Selection, list[Selection]]:
    """The second paper's procedure: greedy from ``n_starts`` random sets of ``n_initial``."""
    n_params = blocks[0].shape[1]
    if len(blocks) * blocks[0].shape[0] < n_params or len(blocks) < n_initial:
        raise IdentifiabilityError(
            f"{len(blocks)} candidates cannot identify {n_params} parameters"
        )
    runs = []
    for _ in range(n_starts):
        start = sorted(rng.choice(len(blocks), size=n_initial, replace=False).tolist())
        runs.append(greedy(blocks, start, until, name))
    return runs[_pick(np.array([r.final for r in runs]), name)], runs


def stopping_count(selection: Selection, rtol: float = 0.01, window: int = 3) -> int:
    """The smallest count after which ``window`` more poses improve the index by less than
    ``rtol`` (relative): where the curve "stops improving"."""
    curve = np.asarray(selection.index_by_count)
    finite = np.isfinite(curve)
    for k in range(len(curve) - window):
        if not finite[k]:
            continue
        ahead = curve[k + window]
        gain = abs(ahead - curve[k]) / max(abs(curve[k]), 1e-300)
        if not better(selection.index_name, ahead, curve[k]) or gain < rtol:
            return selection.start_count + k
    return selection.start_count + len(curve) - 1


def exchange(
    blocks: list[np.ndarray], start: list[int], name: str = "d_optimality", max_sweeps: int = 20
) -> tuple[list[int], float]:
    """Swap selected poses for candidates while that improves the index (fixed count)."""
    stack = _stack(blocks)
    chosen = list(start)
    value = _value(blocks, chosen, name)
    for _ in range(max_sweeps):
        improved = False
        for pos in range(len(chosen)):
            rest = [j for j in range(len(stack)) if j not in chosen]
            if not rest:
                break
            kept = [*chosen[:pos], *chosen[pos + 1 :]]
            values = index_with_each(np.vstack(stack[kept]), stack[rest], name)
            k = _pick(values, name)
            if _gains(name, values[k], value):
                chosen[pos] = rest[k]
                value = float(values[k])
                improved = True
        if not improved:
            break
    return chosen, float(value)
