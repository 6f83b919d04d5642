"""Compensation: commands that put the identified machine where the user asks.

The identified parameters are injected into the nominal model and its exact closed-chain
inverse kinematics gives the actuator commands for each desired tool pose (the controller
would load the same parameters). The result is re-measured on the real machine (the truth
twin in a scenario) to score it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.compensate.poses import solve_each
from calib.fit.model import CalibrationModel
from twin.kinematics.inverse_batch import actuator_twist_jacobians, inverse_near
from twin.kinematics.single_pose import inverse
from twin.rotations import matrix_from_rotvec, matrix_from_rpy, rpy_from_matrix
from twin.workspace import commands_for_poses


def compensated_commands(
    model: CalibrationModel, values: np.ndarray, poses: np.ndarray
) -> np.ndarray:
    """Commands (N, A) for desired poses (N, 6) on the model with ``values`` injected
    (through its joint compliances and actuator gains, if it has any)."""
    return model.commands_for_joints(values, commands_for_poses(model.mechanism(values), poses))


def reachable_compensated_commands(
    model: CalibrationModel, values: np.ndarray, poses: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Like :func:`compensated_commands`, but a pose whose compensated commands leave a
    stroke is reported (mask False, its row NaN) instead of stopping the whole set: near the
    workspace boundary the real machine may not reach what its nominal model could. The
    same solve, pose by pose from home, as ``pkm-calib compensate``
    (calib.compensate.poses.solve_each), the joint values turned into commands through the
    model's joint compliances and actuator gains (if any)."""
    solved = solve_each(model.mechanism(values), poses)
    return model.commands_for_joints(values, solved.commands, solved.qpos), solved.reachable


def corrected_poses(poses: np.ndarray, twists: np.ndarray) -> np.ndarray:
    """Poses (N, 6) moved against their predicted error twists (N, 6): the position by
    ``-twist[:3]``, the orientation turned by ``-twist[3:]`` (world axes); every pose at once,
    the arithmetic of each pose's own element by element."""
    turned = matrix_from_rotvec(-twists[:, 3:]) @ matrix_from_rpy(poses[:, 3:])
    return np.hstack([poses[:, :3] - twists[:, :3], rpy_from_matrix(turned)])


@dataclass(frozen=True)
class TwistCompensation:
    """The estimate-independent part of the first paper's Eq. (16) for a set of poses.

    Each commanded pose's inverse kinematics on the controller's model (nominal geometry with
    the coarse encoder settings ``base_values``) and its tool twist Jacobian ``B`` are computed
    once by :meth:`prepare`; :meth:`commands` then corrects the poses for any number of
    estimates ``delta`` (one inverse kinematics per pose each, started from the first)."""

    model: CalibrationModel
    base_values: np.ndarray
    poses: np.ndarray  # (N, 6)
    qpos: np.ndarray  # (N, nq) the first inverse kinematics of each pose
    twist_jacobians: np.ndarray  # (N, 6, n) d(tool twist)/d(every parameter)
    actuator_jacobians: np.ndarray  # (N, 6, A) d(tool twist)/d(actuator joints) at qpos

    @classmethod
    def prepare(
        cls, model: CalibrationModel, base_values: np.ndarray, poses: np.ndarray
    ) -> TwistCompensation:
        base_values = np.array(base_values, dtype=float)
        poses = np.atleast_2d(np.asarray(poses, dtype=float))
        mech = model.mechanism(base_values)
        # the model's own inverse kinematics of these poses when it has them (the same
        # solves: pose after pose from home), else solved here
        qpos = model.solved_configurations(base_values, poses)
        if qpos is None:
            qpos = np.empty((len(poses), mech.model.nq))
            q = None
            for i, pose in enumerate(poses):  # each pose started from the previous solution
                q = qpos[i] = inverse(mech, pose, start=q).qpos
        jac = model.tool_twist_jacobian(base_values, qpos)
        return cls(model, base_values, poses, qpos, jac, actuator_twist_jacobians(mech, qpos))

    def commands(self, delta: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """Commands (N, A) for the poses corrected by the predicted twist ``B[:, columns]
        delta`` of the estimate ``delta`` (SI, one value per column)."""
        mech = self.model.mechanism(self.base_values)
        twists = self.twist_jacobians[:, :, np.asarray(columns)] @ np.asarray(delta, dtype=float)
        corrected = corrected_poses(self.poses, twists)
        # every pose at once, each from its first inverse kinematics (the same exact inverse
        # kinematics as twin.kinematics.single_pose.inverse, to round-off; the same errors)
        joints, qpos = inverse_near(mech, corrected, self.qpos, self.actuator_jacobians)
        return self.model.commands_for_joints(self.base_values, joints, qpos)


def twist_compensated_commands(
    model: CalibrationModel,
    base_values: np.ndarray,
    delta: np.ndarray,
    columns: np.ndarray,
    poses: np.ndarray,
) -> np.ndarray:
    """The first paper's Eq. (16): each commanded pose is corrected by the predicted pose
    error twist ``B delta`` and turned into commands by the controller's inverse kinematics
    (nominal geometry with the coarse encoder settings ``base_values``). For several
    estimates on the same poses, :class:`TwistCompensation` does the common work once."""
    return TwistCompensation.prepare(model, base_values, poses).commands(delta, columns)
