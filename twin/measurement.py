"""The truth twin measured by a laser tracker: commands in, target readings out.

The twin runs closed-chain forward kinematics of the (error-injected) mechanism, optionally
perturbs the measured tool pose (the second paper's pose-noise model), places the targets,
and passes them through the tracker (distance-dependent noise, repeats, scale error).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.effects.base import ActuatorEffect, apply_actuator_effects
from twin.kinematics import check_commands
from twin.kinematics_batch import forward_batch
from twin.mechanism import Mechanism
from twin.tracker import PoseNoise, Tracker


@dataclass(frozen=True)
class Measurement:
    readings: np.ndarray  # (P, T, R, 3) metres, base frame
    true_targets: np.ndarray  # (P, T, 3)
    true_rotation: np.ndarray  # (P, 3, 3) tool frame
    true_position: np.ndarray  # (P, 3)


def check_commands_batch(mech: Mechanism, commands: np.ndarray) -> None:
    for k, c in enumerate(np.atleast_2d(commands)):
        try:
            check_commands(mech, c)
        except Exception as exc:
            raise type(exc)(f"pose {k}: {exc}") from None


def measure(
    truth: Mechanism,
    commands: np.ndarray,
    tracker: Tracker,
    rng: np.random.Generator,
    pose_noise: PoseNoise | None = None,
    effects: Sequence[ActuatorEffect] = (),
    order: np.ndarray | None = None,
) -> Measurement:
    """Tracker readings of every target at every command row (N, A).

    ``effects`` (thermal growth, lead error, backlash, gravity compliance, ...) turn the
    commands into the joint values the machine really takes, in measurement ``order``.
    """
    check_commands_batch(truth, commands)  # the commands must respect the strokes ...
    joints = apply_actuator_effects(truth, effects, commands, order) if effects else commands
    sol = forward_batch(truth, joints, check_stroke=False)  # ... effects may nudge past them
    targets = sol.targets
    if pose_noise is not None:
        local = truth.target_local()
        r_noisy, p_noisy = pose_noise.perturb(sol.tool_rotation, sol.tool_position, rng)
        targets = np.einsum("nij,tj->nti", r_noisy, local) + p_noisy[:, None, :]
    readings = tracker.measure(targets, rng)
    return Measurement(readings, sol.targets, sol.tool_rotation, sol.tool_position)
