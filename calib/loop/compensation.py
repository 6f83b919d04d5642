"""Compensation with an effect: invert the corrected model by a fixed point on the commands.

The identified machine takes joint values ``c + D(c, t) theta`` for commands c
(calib.loop.effect). For a desired pose the exact inverse kinematics of the identified
geometry gives the joint values q* it must take; the commands are the fixed point of

    c_{i+1} = q* - D(c_i, t) theta,    c_0 = q*,

which converges when the correction changes slowly with the command (|dD theta / dc| < 1:
a gain error of parts per million, a play that flips only with the approach direction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.exceptions import ConvergenceError
from calib.fit.model import CalibrationModel
from calib.loop.effect import ActuatorCorrection
from twin.kinematics.inverse_batch import commands_near
from twin.workspace import commands_for_poses


@dataclass(frozen=True)
class LoopCommands:
    commands: np.ndarray  # (N, A)
    joints: np.ndarray  # (N, A): what the identified machine takes, q*
    iterations: int
    max_change: float  # of the last fixed-point step (SI)


def invert_correction(
    correction: ActuatorCorrection,
    joints: np.ndarray,
    order: np.ndarray,
    tol: float = 1e-12,
    max_iterations: int = 50,
) -> tuple[np.ndarray, int, float]:
    """Commands c with ``c + D(c) theta = joints`` (fixed point); (commands, rounds, change)."""
    q = np.asarray(joints, dtype=float)
    c = q.copy()
    change = np.inf
    for it in range(1, max_iterations + 1):
        new = q - correction.offsets(c, order)
        change = float(np.max(np.abs(new - c))) if c.size else 0.0
        c = new
        if change <= tol:
            return c, it, change
    raise ConvergenceError(
        f"the commands of the corrected model did not settle in {max_iterations} rounds "
        f"(last change {change:.3g}): the effect changes too fast with the command"
    )


def loop_commands(
    model: CalibrationModel,
    values: np.ndarray,
    correction: ActuatorCorrection,
    poses: np.ndarray,
    order: np.ndarray,
    tol: float = 1e-12,
    near: tuple[np.ndarray, np.ndarray] | None = None,
) -> LoopCommands:
    """Commands (N, A) that put the identified machine (geometry ``values`` with the
    effect's correction) at ``poses`` (N, 6) measured in sequence ``order``.

    ``near``: closed configurations (N, nq) of the same poses on a nearby model (e.g. the
    controller's, a calibration's estimate away) and their actuator twist Jacobians
    (N, 6, A): the inverse kinematics then solves every pose at once from them
    (twin.kinematics.inverse_batch.commands_near, the same solutions to round-off)."""
    mech = model.mechanism(values)
    if near is None:
        q_star = commands_for_poses(mech, poses)
    else:
        q_star = commands_near(mech, poses, *near)
    wanted = model.commands_for_joints(values, q_star)  # through the model's gains, if any
    c, it, change = invert_correction(correction, wanted, np.asarray(order), tol)
    return LoopCommands(c, q_star, it, change)
