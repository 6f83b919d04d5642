"""The truth twin measured by a laser tracker: commands in, target readings out.

The twin runs closed-chain forward kinematics of the (error-injected) mechanism, optionally
perturbs the measured tool pose (the second paper's pose-noise model), places the targets,
and passes them through the tracker (distance-dependent noise, repeats, scale error).
Physical effects enter where their physics acts (see :mod:`twin.effects.base`): on the joint
values, on the geometry at each pose in measurement order, on the reflectors, on the tracker.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.effects.base import (
    Effect,
    GeometryEffect,
    apply_actuator_effects,
    check_effects,
    model_at,
    target_offsets,
    tracker_with,
)
from twin.kinematics.batch import forward_batch
from twin.kinematics.single_pose import check_commands
from twin.mechanism import Mechanism
from twin.tracker import PoseNoise, Tracker


@dataclass(frozen=True)
class Measurement:
    readings: np.ndarray  # (P, T, R, 3) metres, base frame
    true_targets: np.ndarray  # (P, T, 3)
    true_rotation: np.ndarray  # (P, 3, 3) tool frame
    true_position: np.ndarray  # (P, 3)


def check_commands_batch(mech: Mechanism, commands: np.ndarray) -> None:
    """check_commands of every row; the first row that fails raises, naming its pose (the
    rows are tested together, the failing one alone again for its message)."""
    c = np.atleast_2d(np.asarray(commands, dtype=float))
    if c.ndim == 2 and c.shape[1] == mech.n_actuators:
        lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
        with np.errstate(invalid="ignore"):
            bad = ~np.all(np.isfinite(c) & (c >= lo - 1e-12) & (c <= hi + 1e-12), axis=1)
        rows = np.flatnonzero(bad)
    else:
        rows = np.arange(len(c))  # the first row's shape is wrong: its own message
    for k in rows:
        try:
            check_commands(mech, c[k])
        except Exception as exc:
            raise type(exc)(f"pose {k}: {exc}") from None


def _models_per_pose(
    truth: Mechanism, effects: Sequence[Effect], order: np.ndarray
) -> list[tuple[Mechanism, np.ndarray]]:
    """Groups of poses (indices) that share one geometry; one group when nothing changes."""
    geometry = [e for e in effects if isinstance(e, GeometryEffect)]
    if not geometry:  # one geometry for every pose
        return [(truth, np.arange(len(order)))]
    groups: dict[int, tuple[Mechanism, list[int]]] = {}
    for i, k in enumerate(order):
        mech = model_at(truth, geometry, int(k))
        groups.setdefault(id(mech), (mech, []))[1].append(i)
    return [(mech, np.array(ids)) for mech, ids in groups.values()]


def measure(
    truth: Mechanism,
    commands: np.ndarray,
    tracker: Tracker,
    rng: np.random.Generator,
    pose_noise: PoseNoise | None = None,
    effects: Sequence[Effect] = (),
    order: np.ndarray | None = None,
) -> Measurement:
    """Tracker readings of every target at every command row (N, A).

    ``effects`` (thermal growth and warm-up, lead error, backlash, gain, compliance,
    reflector offsets, air temperature ...) turn the commands into the joint values the
    machine really takes, the geometry into the one at each pose's time, the reflectors into
    where they really sit and the tracker into how it really measures, in measurement
    ``order`` (default: row order).
    """
    check_commands_batch(truth, commands)  # the commands must respect the strokes ...
    check_effects(effects)
    commands = np.atleast_2d(np.asarray(commands, dtype=float))
    order = np.arange(len(commands)) if order is None else np.asarray(order)
    joints = apply_actuator_effects(truth, effects, commands, order) if effects else commands
    offsets = target_offsets(truth, effects)
    n = len(commands)
    true_r, true_p = np.zeros((n, 3, 3)), np.zeros((n, 3))
    targets = np.zeros((n, truth.n_targets, 3))
    groups = _models_per_pose(truth, effects, order)
    for mech, ids in groups:
        sol = forward_batch(mech, joints[ids], check_stroke=False)  # effects may nudge past
        true_r[ids], true_p[ids] = sol.tool_rotation, sol.tool_position
        targets[ids] = sol.targets
    if np.any(offsets):
        targets = targets + np.einsum("nij,tj->nti", true_r, offsets)
    true_targets = targets
    if pose_noise is not None:
        r_noisy, p_noisy = pose_noise.perturb(true_r, true_p, rng)
        if len(groups) == 1:
            local = groups[0][0].target_local() + offsets
            targets = np.einsum("nij,tj->nti", r_noisy, local) + p_noisy[:, None, :]
        else:  # each pose's own (grown) tool
            local = np.zeros((n, truth.n_targets, 3))
            for mech, ids in groups:
                local[ids] = mech.target_local() + offsets
            targets = np.einsum("nij,ntj->nti", r_noisy, local) + p_noisy[:, None, :]
    readings = tracker_with(tracker, effects).measure(targets, rng)
    return Measurement(readings, true_targets, true_r, true_p)
