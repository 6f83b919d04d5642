"""Commanded tool poses inside a machine's workspace: checks, random draws and grids.

A pose is ``[x, y, z, rx, ry, rz]`` (SI; R = Rz Ry Rx). The workspace box comes from the
MJCF (``workspace_min`` / ``workspace_max``); a pose is reachable when it lies in that box and
the nominal inverse kinematics keeps every actuator inside its stroke.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics.single_pose import inverse
from twin.mechanism import Mechanism

AXES = ("x", "y", "z", "rx", "ry", "rz")


def workspace_box(mech: Mechanism) -> tuple[np.ndarray, np.ndarray]:
    if mech.workspace_min is None or mech.workspace_max is None:
        raise WorkspaceError(
            f"model '{mech.name}' declares no workspace (<numeric name='workspace_min'/'max'>)"
        )
    return mech.workspace_min, mech.workspace_max


def pose_name(i: int, labels: Sequence[object] | None) -> str:
    """How messages name pose ``i``: its dataset ``pose_id`` when labels are given."""
    return f"pose {i}" if labels is None else f"pose_id {labels[i]}"


def check_labels(labels: Sequence[object] | None, n: int) -> None:
    """One label per pose, or none."""
    if labels is not None and len(labels) != n:
        raise ValueError(f"{len(labels)} pose labels for {n} poses")


def _actuator_value(mech: Mechanism, k: int, value: float) -> tuple[str, str]:
    """A command (SI) in the units of files: mm for prismatic, deg for revolute actuators."""
    if mech.actuator_is_slide[k]:
        return f"{value * 1e3:.6g}", "mm"
    return f"{np.degrees(value):.6g}", "deg"


def check_pose_in_box(mech: Mechanism, pose: np.ndarray, tol: float = 1e-12) -> None:
    """Raise WorkspaceError naming the axis when ``pose`` leaves the workspace box."""
    lo, hi = workspace_box(mech)
    pose = np.asarray(pose, dtype=float)
    for k, name in enumerate(AXES):
        if not lo[k] - tol <= pose[k] <= hi[k] + tol:
            scale, unit = (1e3, "mm") if k < 3 else (np.degrees(1.0), "deg")
            raise WorkspaceError(
                f"pose {name} = {pose[k] * scale:.4g} {unit} is outside the workspace "
                f"[{lo[k] * scale:.4g}, {hi[k] * scale:.4g}] {unit}"
            )


def stroke_problem(mech: Mechanism, commands: np.ndarray, tol: float = 1e-12) -> str | None:
    """Why commands (A,) (SI) leave a stroke, in mm or deg (the units of files); None if not."""
    c = np.asarray(commands, dtype=float)
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    for k in np.flatnonzero(~np.isfinite(c) | (c < lo - tol) | (c > hi + tol)):
        k = int(k)
        value, unit = _actuator_value(mech, k, c[k])
        if not np.isfinite(c[k]):
            return f"actuator '{mech.actuator_names[k]}' command is {value}"
        low, _ = _actuator_value(mech, k, lo[k])
        high, _ = _actuator_value(mech, k, hi[k])
        what = "stroke" if mech.actuator_is_slide[k] else "range"
        return (
            f"actuator '{mech.actuator_names[k]}' command {value} {unit} is outside its "
            f"{what} [{low}, {high}] {unit}"
        )
    return None


def check_command_strokes(
    mech: Mechanism, commands: np.ndarray, labels: Sequence[object] | None = None
) -> None:
    """Raise WorkspaceError unless every command row (N, A) (SI) lies inside the strokes.

    The message names the pose (``labels[i]``, e.g. a dataset's ``pose_id``, or else its row
    index), the actuator and the values in mm or deg."""
    c = np.atleast_2d(np.asarray(commands, dtype=float))
    if c.ndim != 2 or c.shape[1] != mech.n_actuators:
        raise WorkspaceError(
            f"expected {mech.n_actuators} actuator commands {mech.actuator_names} per pose, "
            f"got shape {c.shape}"
        )
    check_labels(labels, len(c))
    for i, row in enumerate(c):
        problem = stroke_problem(mech, row)
        if problem:
            raise WorkspaceError(f"{pose_name(i, labels)}: {problem}")


def commands_for_poses(
    mech: Mechanism, poses: np.ndarray, labels: Sequence[object] | None = None
) -> np.ndarray:
    """Commands (N, A) for poses (N, 6): box check, IK, stroke check; errors name the pose.

    ``labels`` (one per pose, e.g. a dataset's ``pose_id`` values) name the poses in errors;
    without them a pose is named by its row index. Values are shown in mm and deg."""
    return solve_poses(mech, poses, labels)[0]


def solve_poses(
    mech: Mechanism, poses: np.ndarray, labels: Sequence[object] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`commands_for_poses` and the closed configurations (N, nq) it solved, each pose
    started from the previous one's solution (the first from home)."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    check_labels(labels, len(poses))
    out = np.empty((len(poses), mech.n_actuators))
    qpos = np.empty((len(poses), mech.model.nq))
    q = None
    for i, p in enumerate(poses):
        try:
            check_pose_in_box(mech, p)
            sol = inverse(mech, p, start=q, check_stroke=False)
            problem = stroke_problem(mech, sol.actuators)
            if problem:
                raise WorkspaceError(f"not reachable: {problem}")
        except (WorkspaceError, ClosureError) as exc:
            raise type(exc)(f"{pose_name(i, labels)}: {exc}") from None
        out[i] = sol.actuators
        q = qpos[i] = sol.qpos
    return out, qpos


def checked_commands(
    mech: Mechanism, poses: np.ndarray, commands: np.ndarray, labels: Sequence[object] | None = None
) -> np.ndarray:
    """The checks of :func:`commands_for_poses` on commands already solved for ``poses`` (by
    the same inverse kinematics elsewhere): each pose in the box, each command in its stroke;
    errors name the pose. Returns the commands (N, A)."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    commands = np.atleast_2d(np.asarray(commands, dtype=float))
    check_labels(labels, len(poses))
    if commands.shape != (len(poses), mech.n_actuators):
        raise WorkspaceError(
            f"expected {len(poses)} x {mech.n_actuators} commands, got shape {commands.shape}"
        )
    for i, (p, c) in enumerate(zip(poses, commands, strict=True)):
        try:
            check_pose_in_box(mech, p)
            problem = stroke_problem(mech, c)
            if problem:
                raise WorkspaceError(f"not reachable: {problem}")
        except WorkspaceError as exc:
            raise WorkspaceError(f"{pose_name(i, labels)}: {exc}") from None
    return commands


def uniform_commands(
    mech: Mechanism, n: int, fraction: float, rng: np.random.Generator
) -> np.ndarray:
    """``n`` commands (N, A) drawn uniformly over ``fraction`` of each actuator's range about
    its middle (an arm's joints; no closure or workspace check)."""
    lo, hi = mech.actuator_range.T
    mid, half = (lo + hi) / 2, fraction * (hi - lo) / 2
    return rng.uniform(mid - half, mid + half, (n, mech.n_actuators))


def random_commands(
    mech: Mechanism, n: int, fraction: float, rng: np.random.Generator
) -> np.ndarray:
    """``n`` commands (N, A) of any machine: a serial arm's uniform over ``fraction`` of each
    range (:func:`uniform_commands`), a closed chain's those of random reachable poses
    (:func:`random_poses`; ``fraction`` does not apply)."""
    if mech.is_serial:
        return uniform_commands(mech, n, fraction, rng)
    return random_poses(mech, n, rng)[1]


def random_poses(
    mech: Mechanism, n: int, rng: np.random.Generator, max_draws: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` uniform random reachable poses and their nominal commands, by rejection.

    Only about a quarter of the hexapod's box keeps every limb in its stroke, so draws that
    leave the stroke are rejected; ``max_draws`` (default 50 n) bounds the effort.
    """
    lo, hi = workspace_box(mech)
    max_draws = max_draws or 50 * n
    poses, cmds = [], []
    draws = 0
    while len(poses) < n:
        if draws >= max_draws:
            raise WorkspaceError(
                f"only {len(poses)} of {n} random poses were reachable in {draws} draws"
            )
        p = rng.uniform(lo, hi)
        draws += 1
        try:
            sol = inverse(mech, p)
        except (WorkspaceError, ClosureError):
            continue
        poses.append(p)
        cmds.append(sol.actuators)
    return np.array(poses), np.array(cmds)


def grid_poses(
    mech: Mechanism,
    nodes_per_axis: int,
    orientations_per_node: int,
    rng: np.random.Generator,
    margin: float = 0.0,
    max_draws_per_node: int = 200,
    stroke_margin: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A nodes^3 grid over the position box, each node with random reachable orientations.

    This is the second paper's verification plan (27 nodes x 8 orientations = 216 poses);
    ``margin`` shrinks the box by that fraction on each side; ``stroke_margin`` (m or rad)
    keeps the nominal commands that far inside the strokes, so that compensated commands,
    which differ by the size of the errors, stay inside too.
    """
    lo_a = mech.actuator_range[:, 0] + stroke_margin
    hi_a = mech.actuator_range[:, 1] - stroke_margin
    lo, hi = workspace_box(mech)
    span = hi - lo
    lo_m, hi_m = lo + margin * span, hi - margin * span
    axes = [np.linspace(lo_m[k], hi_m[k], nodes_per_axis) for k in range(3)]
    poses, cmds = [], []
    for x in axes[0]:
        for y in axes[1]:
            for z in axes[2]:
                found, draws = 0, 0
                while found < orientations_per_node:
                    if draws >= max_draws_per_node:
                        raise WorkspaceError(
                            f"node ({x * 1e3:.1f}, {y * 1e3:.1f}, {z * 1e3:.1f}) mm: only "
                            f"{found} reachable orientations in {draws} draws"
                        )
                    draws += 1
                    p = np.concatenate([[x, y, z], rng.uniform(lo[3:], hi[3:])])
                    try:
                        sol = inverse(mech, p)
                    except (WorkspaceError, ClosureError):
                        continue
                    if np.any(sol.actuators < lo_a) or np.any(sol.actuators > hi_a):
                        continue
                    poses.append(p)
                    cmds.append(sol.actuators)
                    found += 1
    return np.array(poses), np.array(cmds)


def layer_poses(
    mech: Mechanism, heights: list[float], nodes_per_side: int, half_width: tuple[float, float]
) -> np.ndarray:
    """Pure-translation nodes: ``nodes_per_side``^2 evenly spaced nodes in each layer.

    The first paper's calibration plan: layers parallel to xy at ``heights`` (m), nodes over
    [-half_width, +half_width] in x and y, the tool orientation fixed at zero.
    """
    if nodes_per_side < 1:
        raise WorkspaceError(f"a layer needs at least one node per side, got {nodes_per_side}")
    xs = np.linspace(-half_width[0], half_width[0], nodes_per_side) if nodes_per_side > 1 else [0.0]
    ys = np.linspace(-half_width[1], half_width[1], nodes_per_side) if nodes_per_side > 1 else [0.0]
    return np.array([[x, y, z, 0.0, 0.0, 0.0] for z in heights for x in xs for y in ys])


def boundary_poses(mech: Mechanism, tol: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """The 2^6 extremes of the workspace box, each pulled back to the reachable boundary.

    For every corner of the box (all combinations of min/max on the six axes) the pose is
    searched on the segment from the box centre to that corner: the farthest pose along it
    whose nominal inverse kinematics keeps every actuator in its stroke (bisection to ``tol``
    of the segment). Returns the poses (64, 6), their commands, and nothing is silently
    dropped: a corner whose whole segment is unreachable raises.
    """
    import itertools

    lo, hi = workspace_box(mech)
    centre = 0.5 * (lo + hi)
    poses, cmds = [], []
    for bits in itertools.product((0, 1), repeat=6):
        corner = np.where(np.array(bits) == 1, hi, lo)
        best = None
        a, b = 0.0, 1.0
        try:
            best = (0.0, inverse(mech, centre).actuators)
        except (WorkspaceError, ClosureError) as exc:
            raise WorkspaceError(f"the workspace centre is not reachable: {exc}") from None
        try:
            best = (1.0, inverse(mech, corner).actuators)
        except (WorkspaceError, ClosureError):
            while b - a > tol:
                t = 0.5 * (a + b)
                try:
                    best = (t, inverse(mech, centre + t * (corner - centre)).actuators)
                    a = t
                except (WorkspaceError, ClosureError):
                    b = t
        t, c = best
        poses.append(centre + t * (corner - centre))
        cmds.append(c)
    return np.array(poses), np.array(cmds)
