"""The program's order: short travel, calibration and test poses interleaved in time, and
each actuator approaching its commands from both sides.

Distance between two poses is the largest actuator move, each scaled by its range (the
actuators move together, so the slowest one sets the time). The calibration poses are
toured greedily by nearest neighbour from the home commands; each test pose is then inserted
at evenly spaced places of that tour (the test poses spread over the whole campaign, so a
drift shows in both sets alike), each place taking the remaining test pose that lengthens
the travel least. The approach direction of actuator a at a pose, +1 (its command reached
moving up) or -1 (moving down), is the direction of the move into the pose; per set, where
one direction outnumbers the other by more than one, the smallest moves of the majority are
flipped (the controller then overshoots by a small amount and comes back), so each actuator
approaches about half the poses of each set from each side: backlash, a step of the joint
value with the approach side, is then separable from the geometry."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Order:
    sequence: np.ndarray  # indices into the poses, in program order
    directions: np.ndarray  # (N, A) +1/-1 approach per pose of the sequence and actuator
    travel: float  # sum of the scaled moves along the sequence (home first)
    travel_unordered: float  # the same for the poses in the order given


def _step(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.max(np.abs(a - b), axis=-1)


def travel(scaled: np.ndarray, start: np.ndarray) -> float:
    """Sum of the scaled moves through ``scaled`` (N, A) rows from ``start`` (A,)."""
    path = np.vstack([start[None], scaled])
    return float(np.sum(_step(path[1:], path[:-1])))


def nearest_neighbour(scaled: np.ndarray, start: np.ndarray) -> list[int]:
    """Greedy tour of the rows of ``scaled`` from ``start`` (ties: the lower index)."""
    left = list(range(len(scaled)))
    at, tour = start, []
    while left:
        k = left[int(np.argmin(_step(scaled[left], at)))]
        tour.append(k)
        left.remove(k)
        at = scaled[k]
    return tour


def interleave(
    scaled: np.ndarray, start: np.ndarray, tour: list[int], tests: list[int]
) -> list[int]:
    """Insert ``tests`` into ``tour`` at evenly spaced places (module docstring)."""
    out = list(tour)
    left = list(tests)
    n_cal, n_test = len(tour), len(tests)
    for j in range(n_test):
        place = round((j + 0.5) * n_cal / n_test) + j  # earlier insertions shift it
        prev = start if place == 0 else scaled[out[place - 1]]
        nxt = scaled[out[place]] if place < len(out) else None
        cost = _step(scaled[left], prev) + (
            0.0 if nxt is None else _step(scaled[left], nxt) - _step(nxt, prev)
        )
        k = left.pop(int(np.argmin(cost)))
        out.insert(place, k)
    return out


def approach_directions(commands: np.ndarray, start: np.ndarray, sets: np.ndarray) -> np.ndarray:
    """+1/-1 per pose and actuator (module docstring) for ``commands`` (N, A) in program
    order, ``sets`` (N,) the set of each."""
    path = np.vstack([start[None], commands])
    move = np.diff(path, axis=0)
    dirs = np.where(move < 0, -1, 1)
    for name in np.unique(sets):
        rows = np.flatnonzero(sets == name)
        for a in range(commands.shape[1]):
            d = dirs[rows, a]
            while abs(int(d.sum())) > 1:
                major = 1 if d.sum() > 0 else -1
                cand = np.flatnonzero(d == major)
                k = cand[int(np.argmin(np.abs(move[rows[cand], a])))]
                d[k] = -major
            dirs[rows, a] = d
    return dirs


def order_program(
    commands: np.ndarray, ranges: np.ndarray, home: np.ndarray, is_test: np.ndarray
) -> Order:
    """The program order of ``commands`` (N, A) (SI), ``ranges`` (A,) each actuator's range,
    ``home`` (A,) where the machine starts, ``is_test`` (N,) the test poses."""
    scaled = np.asarray(commands, dtype=float) / ranges
    start = np.asarray(home, dtype=float) / ranges
    is_test = np.asarray(is_test, dtype=bool)
    cal, tests = np.flatnonzero(~is_test), np.flatnonzero(is_test).tolist()
    tour = [int(cal[k]) for k in nearest_neighbour(scaled[cal], start)]
    seq = np.array(interleave(scaled, start, tour, tests) if tests else tour, dtype=int)
    sets = np.where(is_test[seq], "test", "calibration")
    dirs = approach_directions(np.asarray(commands)[seq], np.asarray(home, float), sets)
    return Order(seq, dirs, travel(scaled[seq], start), travel(scaled, start))
