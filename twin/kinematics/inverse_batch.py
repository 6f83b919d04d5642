"""Batched inverse kinematics near known solutions: many poses at once through forward_batch.

For poses close to configurations already solved (a compensation moves each commanded pose
by the predicted error, tenths of a millimetre), the commands are found by a chord Newton
iteration on the actuator commands themselves:

    c_{k+1} = c_k + J^-1 e(c_k),     e = [p_goal - p_tool, rotvec(R_goal R_tool^T)],

with the tool pose of c_k from the batched exact forward kinematics (twin.kinematics.batch)
and J = d(tool twist)/d(actuator joints) (6 x A, world axes) held at the known configuration.
The error contracts by about |J(c) - J(c_0)| / |J| per step (1e-4 for a tenth of a
millimetre on a machine of a metre): a few steps reach round-off, where the iteration stops
(the residual no longer halves). A pose whose tool error is then not below the single-pose
solver's tolerance (twin.kinematics.single_pose.TOLERANCE), or any pose of a machine without as many
actuators as tool degrees of freedom (6), is solved by twin.kinematics.single_pose.inverse from its
known
configuration, so the result is always that of an exact inverse kinematics on the same
assembly branch, and the errors (unreachable pose, command outside its stroke) are those of
twin.kinematics.single_pose.inverse.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics.batch import forward_batch
from twin.kinematics.sensitivity_batch import tool_twist_jacobian_batch
from twin.kinematics.single_pose import TOLERANCE, check_commands, inverse, pose_to_frame
from twin.kinematics.structure import one_blas_thread
from twin.mechanism import Mechanism
from twin.parameters import Parameter, ParameterSet
from twin.rotations import rotvec_from_matrix
from twin.workspace import check_labels, check_pose_in_box, checked_commands, pose_name

MAX_STEPS = 12
STALL = 0.5  # a step that does not halve the largest tool error ends a pose's iteration


def actuator_joint_parameters(mech: Mechanism) -> ParameterSet:
    """One joint-zero parameter per actuator: its derivative is that of the joint value."""
    return ParameterSet(
        [
            Parameter(f"actuator.{n}", "joint_zero", mech.model.joint(int(j)).name)
            for n, j in zip(mech.actuator_names, mech.actuator_joints, strict=True)
        ],
        mech.model,
    )


def actuator_twist_jacobians(mech: Mechanism, qpos: np.ndarray) -> np.ndarray:
    """d(tool twist)/d(actuator joint values) (N, 6, A) at closed configurations (N, nq)."""
    params = actuator_joint_parameters(mech)
    return tool_twist_jacobian_batch(mech, params, np.zeros(len(params)), qpos)


def tool_errors(
    goal_r: np.ndarray, goal_p: np.ndarray, rot: np.ndarray, pos: np.ndarray
) -> np.ndarray:
    """Twists (N, 6) from the tool frames (rot (N, 3, 3), pos (N, 3)) to the goals."""
    return np.hstack([goal_p - pos, rotvec_from_matrix(goal_r @ np.transpose(rot, (0, 2, 1)))])


def inverse_near(
    mech: Mechanism,
    poses: np.ndarray,
    start: np.ndarray,
    jacobians: np.ndarray | None = None,
    check_stroke: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Commands (N, A) and closed configurations (N, nq) that put the tool at ``poses`` (N, 6),
    each solved from the nearby closed configuration ``start`` (N, nq); ``jacobians``
    (N, 6, A) of :func:`actuator_twist_jacobians` at ``start`` when already computed.

    ``check_stroke``: raise WorkspaceError, as twin.kinematics.single_pose.inverse does, for the
    first
    pose whose commands leave a stroke."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    start = np.atleast_2d(np.asarray(start, dtype=float))
    if start.shape != (len(poses), mech.model.nq):
        raise ValueError(
            f"expected {len(poses)} starts of {mech.model.nq} values, got {start.shape}"
        )
    if mech.n_actuators != 6 or not np.all(np.isfinite(poses)):
        # the chord step needs a square J; bad poses get the single-pose solver's message
        c, q = _one_by_one(mech, poses, start, np.arange(len(poses)))
    else:
        jac = actuator_twist_jacobians(mech, start) if jacobians is None else jacobians
        try:
            c, q, failed = _chord_newton(mech, poses, start, jac)
        except ClosureError:  # a trial step left the closures' reach: every pose alone
            failed = np.arange(len(poses))
            c, q = np.empty((len(poses), mech.n_actuators)), np.empty_like(start)
        if failed.size:
            c[failed], q[failed] = _one_by_one(mech, poses, start, failed)
    if check_stroke:  # every row tested at once; the first failing one raises its message
        lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
        with np.errstate(invalid="ignore"):
            ok = np.all(np.isfinite(c) & (c >= lo - 1e-12) & (c <= hi + 1e-12), axis=1)
        for i in np.flatnonzero(~ok):
            _check_stroke(mech, poses[i], c[i])
    return c, q


def _chord_newton(
    mech: Mechanism, poses: np.ndarray, start: np.ndarray, jac: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    goal_r, goal_p = pose_to_frame(poses)
    with one_blas_thread():
        step_map = np.linalg.inv(jac)  # (N, A, 6)
        c = mech.commands_of_joints(start[:, mech.actuator_qpos]).copy()
        q = start.copy()
        best = np.full(len(poses), np.inf)
        best_c, best_q = c.copy(), q.copy()
        active = np.ones(len(poses), dtype=bool)
        for _ in range(MAX_STEPS):
            idx = np.flatnonzero(active)
            if idx.size == 0:
                break
            sol = forward_batch(mech, c[idx], start=q[idx], check_stroke=False)
            q[idx] = sol.qpos
            e = tool_errors(goal_r[idx], goal_p[idx], sol.tool_rotation, sol.tool_position)
            err = np.max(np.abs(e), axis=1)
            better = err < best[idx]
            keep = idx[better]
            best_c[keep], best_q[keep] = c[keep], q[keep]
            halved = (err < STALL * best[idx]) & (err > 0)
            best[keep] = err[better]
            active[idx[~halved]] = False  # round-off reached (or exact): its best is kept
            move = idx[halved]
            c[move] += np.einsum("naj,nj->na", step_map[move], e[halved])
    return best_c, best_q, np.flatnonzero(~(best < TOLERANCE))


def _check_stroke(mech: Mechanism, pose: np.ndarray, commands: np.ndarray) -> None:
    try:
        check_commands(mech, commands)
    except WorkspaceError as exc:
        raise WorkspaceError(f"pose {pose} is not reachable: {exc}") from None


def _one_by_one(
    mech: Mechanism, poses: np.ndarray, start: np.ndarray, which: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    c = np.empty((len(which), mech.n_actuators))
    q = np.empty((len(which), mech.model.nq))
    for k, i in enumerate(which):
        sol = inverse(mech, poses[i], start=start[i], check_stroke=False)
        c[k], q[k] = sol.actuators, sol.qpos
    return c, q


def commands_near(
    mech: Mechanism,
    poses: np.ndarray,
    start: np.ndarray,
    jacobians: np.ndarray | None = None,
    labels: Sequence[object] | None = None,
) -> np.ndarray:
    """:func:`twin.workspace.commands_for_poses` (box check, inverse kinematics, stroke
    check; errors name the pose) with every pose solved at once from a nearby configuration
    ``start`` (N, nq), e.g. the same poses solved on a model a calibration's estimate away;
    ``jacobians`` (N, 6, A) at ``start`` (or near it: the chord step only needs them
    approximately). Equal to commands_for_poses's solution to round-off where both start on
    the same assembly branch."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    check_labels(labels, len(poses))
    for i, p in enumerate(poses):
        try:
            check_pose_in_box(mech, p)
        except WorkspaceError as exc:
            raise WorkspaceError(f"{pose_name(i, labels)}: {exc}") from None
    try:
        out = inverse_near(mech, poses, start, jacobians, check_stroke=False)[0]
    except (WorkspaceError, ClosureError):  # name the pose: solve them one by one
        out = np.empty((len(poses), mech.n_actuators))
        for i, p in enumerate(poses):
            try:
                out[i] = inverse(mech, p, start=start[i], check_stroke=False).actuators
            except (WorkspaceError, ClosureError) as exc:
                raise type(exc)(f"{pose_name(i, labels)}: {exc}") from None
    return checked_commands(mech, poses, out, labels)  # each command in its stroke
