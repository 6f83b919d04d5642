"""Batched inverse kinematics near known solutions equals the per-pose solver on every machine."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics.inverse_batch import actuator_twist_jacobians, commands_near, inverse_near
from twin.kinematics.single_pose import forward, inverse
from twin.mechanism import Mechanism
from twin.rotations import rpy_from_matrix
from twin.workspace import commands_for_poses, workspace_box

ROOT = Path(__file__).resolve().parent.parent
MACHINES = ["hexapod_rrrprr.xml", "polisher.xml", "arm6r.xml"]


def _near(mech: Mechanism, n: int, seed: int):
    """Poses of commands near home (every machine, with or without a declared workspace),
    their closed configurations, and the poses moved by up to 0.2 mm and 0.2 mrad."""
    rng = np.random.default_rng(seed)
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    home = np.asarray(mech.home_qpos)[mech.actuator_qpos]
    cmds = np.clip(home + rng.uniform(-0.05, 0.05, (n, len(lo))) * (hi - lo), lo, hi)
    sols = [forward(mech, c) for c in cmds]
    poses = np.array(
        [np.concatenate([s.tool_position, rpy_from_matrix(s.tool_rotation)]) for s in sols]
    )
    start = np.array([s.qpos for s in sols])
    moved = poses + rng.uniform(-1, 1, poses.shape) * np.array([2e-4] * 3 + [2e-4] * 3)
    return poses, moved, start


@pytest.mark.parametrize("xml", MACHINES)
def test_batch_equals_the_per_pose_inverse(xml):
    mech = Mechanism.from_xml(ROOT / "models" / xml)
    _, moved, start = _near(mech, 6, 11)
    expected = np.array(
        [inverse(mech, p, start=q).actuators for p, q in zip(moved, start, strict=True)]
    )
    c, q = inverse_near(mech, moved, start)
    np.testing.assert_allclose(c, expected, atol=1e-12)
    np.testing.assert_allclose(q[:, mech.actuator_qpos], c, atol=0)
    for pose, cmd in zip(moved, c, strict=True):  # the tool where asked, to 1e-12 m
        sol = forward(mech, cmd, start=q[0])
        target = inverse(mech, pose, start=sol.qpos)  # its own tool pose check
        np.testing.assert_allclose(sol.tool_position, target.tool_position, atol=1e-12)
    jac = actuator_twist_jacobians(mech, start)
    np.testing.assert_allclose(inverse_near(mech, moved, start, jac)[0], c, atol=0)


def test_unreachable_poses_raise_as_the_per_pose_solver():
    mech = Mechanism.from_xml(ROOT / "models" / "polisher.xml")
    _, moved, start = _near(mech, 3, 12)
    for axis, value in ((0, 10.0), (3, 3.0)):  # 10 m away; turned by 3 rad
        far = moved.copy()
        far[1, axis] = value
        with pytest.raises((ClosureError, WorkspaceError)) as per_pose:
            inverse(mech, far[1], start=start[1])
        with pytest.raises(type(per_pose.value)) as batch:
            inverse_near(mech, far, start)
        assert str(batch.value) == str(per_pose.value)
    with pytest.raises(WorkspaceError, match="a commanded pose is 6 finite numbers"):
        inverse_near(mech, np.where(np.arange(6) == 2, np.nan, moved), start)
    lo = mech.actuator_range[:, 0]
    narrow = Mechanism.from_xml(ROOT / "models" / "polisher.xml")
    narrow.actuator_range[:, 0] = np.maximum(lo, start[:, mech.actuator_qpos].max(axis=0) + 1e-3)
    with pytest.raises(WorkspaceError, match="is not reachable"):
        inverse_near(narrow, moved, start)
    c, _ = inverse_near(narrow, moved, start, check_stroke=False)
    np.testing.assert_allclose(c, inverse_near(mech, moved, start)[0], atol=0)


@pytest.mark.parametrize("xml", ["polisher.xml", "hexapod_rrrprr.xml"])
def test_commands_near_equal_commands_for_poses_on_another_model(xml):
    """Solved from the configurations of a model 1 mm / 1 mrad away, as liu_vs_ols solves the
    uncalibrated and the loop's commands from the controller's model."""
    mech = Mechanism.from_xml(ROOT / "models" / xml)
    lo, hi = workspace_box(mech)
    rng = np.random.default_rng(13)
    poses = lo + (hi - lo) * rng.uniform(0.3, 0.7, (5, 6))
    other = Mechanism.from_xml(ROOT / "models" / xml)
    other.model.body_pos[1:] += rng.uniform(-1e-3, 1e-3, other.model.body_pos[1:].shape)
    start = np.array([inverse(other, p).qpos for p in poses])
    jac = actuator_twist_jacobians(other, start)
    expected = commands_for_poses(mech, poses)
    np.testing.assert_allclose(commands_near(mech, poses, start, jac), expected, atol=1e-12)
    far = poses.copy()
    far[3, 0] = 10.0
    with pytest.raises(WorkspaceError, match="pose 3"):
        commands_near(mech, far, start, jac)
