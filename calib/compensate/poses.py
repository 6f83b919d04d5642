"""Commands for desired tool poses, pose by pose, each one's failure named and the others kept.

The one path from desired poses to actuator commands on any machine (serial, parallel or
hybrid): each pose checked against the workspace box the model declares (if any), then the
exact inverse kinematics (twin.kinematics.single_pose.inverse, the scenarios' own), then the strokes
(a revolute actuator past its range by a whole turn is turned back: the same pose).
A pose that fails is named with the reason, in the units of files: which actuator and by
how much it would leave its stroke, the axis that leaves the workspace, or an inverse
kinematics that does not converge. ``compensate`` runs it on the identified machine for the
poses a user asks for (started from the nominal solution of each, so that both stay on the
same branch), turns the joint values into commands through the identified joint
compliances and actuator gains (if any; their strokes checked again), and gives the residual
the identified model predicts at the commands and the error it predicts for the nominal
commands.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.compensate.identified_machine import IdentifiedMachine
from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics.batch import forward_batch
from twin.kinematics.single_pose import forward, newton_solve, pose_to_frame
from twin.mechanism import Mechanism
from twin.rotations import rotation_angle
from twin.workspace import check_pose_in_box

UNREACHABLE = (
    "out of reach: the inverse kinematics did not converge (the pose lies beyond what the "
    "machine reaches, or at a singularity)"
)


# a residual the solves leave below this (mm or deg) is their round-off, whose digits differ
# from CPU to CPU: said as a bound, not as digits
ROUND_OFF = 1e-6


def shown_residual(value: float, unit: str) -> str:
    """A predicted residual in words: its value, or below ROUND_OFF where it is round-off."""
    return f"below {ROUND_OFF:g} {unit}" if value < ROUND_OFF else f"{value:.3g} {unit}"


def _file_units(mech: Mechanism, k: int, value: float) -> tuple[float, str]:
    return (value * 1e3, "mm") if mech.actuator_is_slide[k] else (float(np.degrees(value)), "deg")


def stroke_excess(mech: Mechanism, commands: np.ndarray, tol: float = 1e-12) -> str | None:
    """Which actuators ``commands`` (A,) (SI) take past their strokes, and by how much, in
    mm or deg; None when every command is inside."""
    c = np.asarray(commands, dtype=float)
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    out = []
    for k in np.flatnonzero(~np.isfinite(c) | (c < lo - tol) | (c > hi + tol)):
        k = int(k)
        name = mech.actuator_names[k]
        if not np.isfinite(c[k]):
            out.append(f"actuator '{name}' gets no finite command")
            continue
        value, unit = _file_units(mech, k, c[k])
        past, _ = _file_units(mech, k, c[k] - hi[k] if c[k] > hi[k] else lo[k] - c[k])
        low, _ = _file_units(mech, k, lo[k])
        high, _ = _file_units(mech, k, hi[k])
        what = "stroke" if mech.actuator_is_slide[k] else "range"
        out.append(
            f"actuator '{name}' needs {value:.6g} {unit}, {past:.4g} {unit} past its {what} "
            f"[{low:.6g}, {high:.6g}] {unit}"
        )
    return "; ".join(out) if out else None


def within_turns(mech: Mechanism, qpos: np.ndarray) -> np.ndarray:
    """``qpos`` with each revolute actuator outside its range turned by whole turns into it
    where a whole turn brings it there (the same pose of the machine)."""
    q = np.array(qpos, dtype=float)
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    for k in np.flatnonzero(~mech.actuator_is_slide):
        a = mech.actuator_qpos[k]
        if lo[k] <= q[a] <= hi[k]:
            continue
        for turns in (1, -1, 2, -2):
            if lo[k] <= q[a] + 2 * np.pi * turns <= hi[k]:
                q[a] += 2 * np.pi * turns
                break
    return q


@dataclass(frozen=True)
class SolvedPoses:
    commands: np.ndarray  # (N, A) SI, NaN where not reachable
    qpos: np.ndarray  # (N, nq), NaN where not reachable
    problems: tuple[str | None, ...]  # why each pose is not reachable (None: it is)

    @property
    def reachable(self) -> np.ndarray:
        return np.array([p is None for p in self.problems], dtype=bool)


def solve_frames(
    mech: Mechanism,
    rotations: np.ndarray,
    positions: np.ndarray,
    starts: np.ndarray | None = None,
    poses: np.ndarray | None = None,
    skip: tuple[str | None, ...] | None = None,
) -> SolvedPoses:
    """Commands for each tool frame (rotation (N, 3, 3), position (N, 3), SI) on ``mech``,
    each solved on its own from ``starts[i]`` (a configuration; a row of NaN or None: from
    home). ``poses`` (N, 6): the same frames as [x y z rx ry rz], checked against the
    workspace box the model declares (if any); ``skip``: a reason per frame not to solve it
    (None: solve), which becomes its problem."""
    commands = np.full((len(positions), mech.n_actuators), np.nan)
    qpos = np.full((len(positions), mech.model.nq), np.nan)
    problems: list[str | None] = []
    boxed = poses is not None and mech.workspace_min is not None and mech.workspace_max is not None
    for i in range(len(positions)):
        if skip is not None and skip[i] is not None:
            problems.append(skip[i])
            continue
        start = None if starts is None or not np.all(np.isfinite(starts[i])) else starts[i]
        q0 = np.array(mech.home_qpos if start is None else start, dtype=float)
        goal = (rotations[i], positions[i])
        try:
            if boxed:
                check_pose_in_box(mech, poses[i])
            q, _, _ = newton_solve(mech, q0, np.arange(mech.model.nv), goal, "inverse kinematics")
        except WorkspaceError as exc:
            problems.append(str(exc))
            continue
        except ClosureError:
            problems.append(UNREACHABLE)
            continue
        q = within_turns(mech, q)
        problem = stroke_excess(mech, q[mech.actuator_qpos])
        problems.append(problem)
        if problem is None:
            commands[i], qpos[i] = q[mech.actuator_qpos], q
    return SolvedPoses(commands, qpos, tuple(problems))


def solve_each(mech: Mechanism, poses: np.ndarray, starts: np.ndarray | None = None) -> SolvedPoses:
    """Commands for each pose (N, 6) (SI) on ``mech``, each solved on its own from
    ``starts[i]`` (a configuration; a row of NaN or None: from home)."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    skip = tuple(
        None if np.all(np.isfinite(p)) else f"a pose is 6 finite numbers [x y z rx ry rz], got {p}"
        for p in poses
    )
    rotations, positions = pose_to_frame(poses)
    return solve_frames(mech, rotations, positions, starts, poses=poses, skip=skip)


def tool_and_targets(
    mech: Mechanism, joints: np.ndarray, start: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Tool points (N, 3) and reflectors (N, T, 3) at the actuated joints' values ``joints``
    (N, A), from the configurations ``start`` (N, nq); NaN where a row cannot be evaluated."""
    return _tool_at(mech, joints, start, with_targets=True)[1:]


def _tool_at(mech: Mechanism, joints: np.ndarray, start: np.ndarray, with_targets: bool = False):
    """Tool rotations (N, 3, 3) and positions (N, 3) at the actuated joints' values ``joints``
    (rows of NaN stay NaN; a gain may take a joint a few ppm past its stroke)."""
    rot = np.full((len(joints), 3, 3), np.nan)
    pos = np.full((len(joints), 3), np.nan)
    targets = np.full((len(joints), len(mech.target_names), 3), np.nan)
    ok = np.all(np.isfinite(joints), axis=1) & np.all(np.isfinite(start), axis=1)
    if np.any(ok):
        try:
            sol = forward_batch(mech, joints[ok], start=start[ok], check_stroke=False)
            rot[ok], pos[ok], targets[ok] = sol.tool_rotation, sol.tool_position, sol.targets
        except (ClosureError, WorkspaceError):  # one by one, leaving out those that fail
            for i in np.flatnonzero(ok):
                try:
                    one = forward(mech, joints[i], start=start[i], check_stroke=False)
                except (ClosureError, WorkspaceError):
                    continue
                rot[i], pos[i], targets[i] = one.tool_rotation, one.tool_position, one.targets
    return (rot, pos, targets) if with_targets else (rot, pos)


@dataclass(frozen=True)
class Compensation:
    """Commands for desired tool frames (base frame) on the identified machine."""

    pose_ids: tuple[str, ...]
    rotations: np.ndarray  # (N, 3, 3) desired tool orientations, base frame
    positions: np.ndarray  # (N, 3) desired tool points, base frame, SI
    commands: np.ndarray  # (N, A) SI, NaN where not reachable
    problems: tuple[str | None, ...]
    residual_m: np.ndarray  # (N,) tool position the identified model predicts at the commands
    residual_rad: np.ndarray  # (N,) its tool orientation error there
    nominal_commands: np.ndarray  # (N, A) the nominal model's commands, NaN where it fails
    nominal_error_m: np.ndarray  # (N,) the identified model's error for the nominal commands
    nominal_qpos: np.ndarray | None = None  # (N, nq) the nominal configurations (the branch)
    # (N,) RMS over the reflectors of the nominal commands' error (calib.compensate.before)
    nominal_reflector_error_m: np.ndarray | None = None

    @property
    def reachable(self) -> np.ndarray:
        return np.array([p is None for p in self.problems], dtype=bool)


def compensate(
    machine: IdentifiedMachine,
    poses: np.ndarray,
    pose_ids: tuple[str, ...],
    starts: np.ndarray | None = None,
) -> Compensation:
    """Commands that put the identified machine's tool at ``poses`` (N, 6) (base frame,
    SI), each started from the nominal model's solution of the same pose (itself started
    from ``starts[i]``, a configuration of the nominal model: a seed's branch; else home)."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    nominal = solve_each(machine.nominal, poses, starts)
    return compensate_frames(machine, pose_ids, *pose_to_frame(poses), nominal, poses)


def compensate_frames(
    machine: IdentifiedMachine,
    pose_ids: tuple[str, ...],
    rotations: np.ndarray,
    positions: np.ndarray,
    nominal: SolvedPoses,
    poses: np.ndarray | None = None,
    skip: tuple[str | None, ...] | None = None,
) -> Compensation:
    """Commands that put the identified machine's tool frame at ``rotations`` (N, 3, 3),
    ``positions`` (N, 3) (base frame, SI), each solved from ``nominal.qpos[i]`` (the nominal
    model's configuration for the same frame: the same branch) and turned into commands
    through the identified gains and compliances; ``nominal.commands``: the commands the
    error of which is predicted (what compensation corrects). ``poses``: the frames as
    [x y z rx ry rz] for the workspace box; ``skip``: a reason per frame not to solve it."""
    solved = solve_frames(machine.mechanism, rotations, positions, nominal.qpos, poses, skip)
    commands = machine.commands_for_joints(solved.commands, solved.qpos)
    problems = list(solved.problems)
    for i in np.flatnonzero(solved.reachable):  # a gain may take a command past its stroke
        excess = stroke_excess(machine.nominal, commands[i])
        if excess:
            problems[i] = (
                f"{excess} (the command, through the identified actuator gain or compliance)"
            )
            commands[i] = np.nan
    reachable = np.array([p is None for p in problems], dtype=bool)
    # what the identified machine does with the written commands (the gains' round trip)
    rot, pos = _tool_at(machine.mechanism, machine.joints_for_commands(commands), solved.qpos)
    turn = rotation_angle(np.swapaxes(rotations, -1, -2) @ np.nan_to_num(rot))
    residual_rad = np.where(reachable, turn, np.nan)
    nominal_joints = machine.joints_for_commands(nominal.commands)
    _, nominal_pos = _tool_at(machine.mechanism, nominal_joints, nominal.qpos)
    return Compensation(
        pose_ids=tuple(pose_ids),
        rotations=rotations,
        positions=positions,
        commands=commands,
        problems=tuple(problems),
        residual_m=np.linalg.norm(pos - positions, axis=1),
        residual_rad=residual_rad,
        nominal_commands=nominal.commands,
        nominal_error_m=np.linalg.norm(nominal_pos - positions, axis=1),
        nominal_qpos=nominal.qpos,
    )
