"""Exact closed-chain forward and inverse kinematics (Newton on the closure residual).

Forward kinematics holds the actuated joints at their commands and solves every other
degree of freedom so that all closures hold; inverse kinematics holds the tool site at a
commanded pose and solves every degree of freedom, actuators included, then reads the
actuator values. Both start from the ``home`` keyframe (or a given configuration) and step
with ``mj_integratePos``; a solve that does not reach the tolerance raises ClosureError.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics.closure import closure_jacobian, closure_residual, update_kinematics
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rpy, rotvec_from_matrix

TOLERANCE = 1e-13  # metres / radians, on the largest closure residual component
ACCEPT = 1e-12  # a solve that stalls below this is accepted; above it, it fails
MAX_ITER = 40
MAX_STEP = 1.0  # largest Newton step (norm, mixed m/rad) before damping


@dataclass(frozen=True)
class Solution:
    """A closed configuration and what the tracker and controller see of it."""

    qpos: np.ndarray
    tool_rotation: np.ndarray  # (3, 3) world <- tool
    tool_position: np.ndarray  # (3,)
    targets: np.ndarray  # (T, 3) world
    actuators: np.ndarray  # (A,)
    residual: float
    iterations: int


def pose_to_frame(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[x, y, z, rx, ry, rz] (SI, R = Rz Ry Rx) -> (R, p)."""
    pose = np.asarray(pose, dtype=float)
    return matrix_from_rpy(pose[..., 3:]), pose[..., :3]


def _tool_residual(mech: Mechanism, goal_r: np.ndarray, goal_p: np.ndarray) -> np.ndarray:
    d = mech.data
    r = d.site_xmat[mech.tool_site].reshape(3, 3)
    return np.concatenate([d.site_xpos[mech.tool_site] - goal_p, rotvec_from_matrix(r @ goal_r.T)])


def _tool_jacobian(mech: Mechanism) -> np.ndarray:
    jp = np.zeros((3, mech.model.nv))
    jr = np.zeros((3, mech.model.nv))
    mujoco.mj_jacSite(mech.model, mech.data, jp, jr, mech.tool_site)
    return np.vstack([jp, jr])


def newton_solve(
    mech: Mechanism,
    qpos: np.ndarray,
    free: np.ndarray,
    goal: tuple[np.ndarray, np.ndarray] | None = None,
    what: str = "forward kinematics",
) -> tuple[np.ndarray, float, int]:
    """Solve closures (and a tool goal) over the dofs ``free``; returns (qpos, residual, iters)."""
    m = mech.model
    q = np.array(qpos, dtype=float)
    best = np.inf
    stall = 0
    for it in range(MAX_ITER + 1):
        update_kinematics(mech, q)
        r = closure_residual(mech)
        if goal is not None:
            r = np.concatenate([r, _tool_residual(mech, *goal)])
        err = float(np.max(np.abs(r))) if r.size else 0.0  # a serial chain: nothing to solve
        if not np.isfinite(err):
            break
        if err < TOLERANCE:
            return q, err, it
        stall = stall + 1 if err >= 0.5 * best else 0
        best = min(best, err)
        if stall >= 3 and best < ACCEPT:
            return q, err, it
        jac = closure_jacobian(mech)
        if goal is not None:
            jac = np.vstack([jac, _tool_jacobian(mech)])
        a = jac[:, free]
        if a.shape[0] == a.shape[1]:
            try:
                step = np.linalg.solve(a, -r)
            except np.linalg.LinAlgError:
                step = np.linalg.lstsq(a, -r, rcond=None)[0]
        else:
            step = np.linalg.lstsq(a, -r, rcond=None)[0]
        norm = float(np.linalg.norm(step))
        if norm > MAX_STEP:
            step *= MAX_STEP / norm
        dq = np.zeros(m.nv)
        dq[free] = step
        mujoco.mj_integratePos(m, q, dq, 1.0)
    raise ClosureError(
        f"{what} of '{mech.name}' did not converge: closure residual {err:.3g} after "
        f"{MAX_ITER} Newton steps (a pose outside the reachable workspace, a singular "
        "configuration, or a start on another assembly branch)"
    )


def check_commands(mech: Mechanism, commands: np.ndarray, stroke: bool = True) -> np.ndarray:
    """Validate actuator commands (A,) against shape, finiteness and (``stroke``) the limits."""
    c = np.asarray(commands, dtype=float)
    if c.shape != (mech.n_actuators,):
        raise WorkspaceError(
            f"expected {mech.n_actuators} actuator commands {mech.actuator_names}, got {c.shape}"
        )
    if not np.all(np.isfinite(c)):
        raise WorkspaceError(f"non-finite actuator command: {c}")
    if not stroke:
        return c
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    bad = np.flatnonzero((c < lo - 1e-12) | (c > hi + 1e-12))
    if bad.size:
        k = int(bad[0])
        slide = bool(mech.actuator_is_slide[k])
        what, unit = ("stroke", "mm") if slide else ("range", "deg")
        show = (lambda v: v * 1e3) if slide else np.degrees  # the units of files
        raise WorkspaceError(
            f"actuator '{mech.actuator_names[k]}' command {show(c[k]):.6g} {unit} is outside "
            f"its {what} [{show(lo[k]):.6g}, {show(hi[k]):.6g}] {unit}"
        )
    return c


def _solution(mech: Mechanism, q: np.ndarray, err: float, it: int) -> Solution:
    update_kinematics(mech, q)
    d = mech.data
    return Solution(
        qpos=q,
        tool_rotation=d.site_xmat[mech.tool_site].reshape(3, 3).copy(),
        tool_position=d.site_xpos[mech.tool_site].copy(),
        targets=d.site_xpos[mech.target_sites].copy(),
        actuators=mech.commands_of_joints(q[mech.actuator_qpos]).copy(),
        residual=err,
        iterations=it,
    )


def forward(
    mech: Mechanism,
    commands: np.ndarray,
    start: np.ndarray | None = None,
    check_stroke: bool = True,
) -> Solution:
    """Closed-chain forward kinematics for actuator commands (A,) (SI).

    ``check_stroke=False`` is for joint values that effects (deflection, backlash) move a
    few micrometres past a limit the command itself respects."""
    c = check_commands(mech, commands, stroke=check_stroke)
    q = np.array(mech.home_qpos if start is None else start, dtype=float)
    q[mech.actuator_qpos] = mech.joints_of_commands(c)
    q, err, it = newton_solve(mech, q, mech.free_dofs())
    return _solution(mech, q, err, it)


def inverse(
    mech: Mechanism,
    pose: np.ndarray,
    start: np.ndarray | None = None,
    check_stroke: bool = True,
) -> Solution:
    """Actuator values that put the tool at ``pose`` = [x, y, z, rx, ry, rz] (SI)."""
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (6,) or not np.all(np.isfinite(pose)):
        raise WorkspaceError(f"a commanded pose is 6 finite numbers [x y z rx ry rz], got {pose}")
    goal = pose_to_frame(pose)
    q0 = np.array(mech.home_qpos if start is None else start, dtype=float)
    q, err, it = newton_solve(
        mech, q0, np.arange(mech.model.nv), goal=goal, what="inverse kinematics"
    )
    sol = _solution(mech, q, err, it)
    if check_stroke:
        try:
            check_commands(mech, sol.actuators)
        except WorkspaceError as exc:
            raise WorkspaceError(f"pose {pose} is not reachable: {exc}") from None
    return sol
