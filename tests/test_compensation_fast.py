"""Compensation by the predicted pose error twist (the first paper's Eq. 16), prepared once.

TwistCompensation computes each pose's first inverse kinematics and twist Jacobian once and
corrects the poses for many estimates; it must give exactly the commands of the per-pose
procedure written out here, and no correction for a zero estimate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.compensate.compensation import TwistCompensation, twist_compensated_commands
from calib.fit.model import CalibrationModel
from twin.exceptions import WorkspaceError
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.sensitivity import tool_twist_jacobian
from twin.kinematics.single_pose import inverse
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rotvec, matrix_from_rpy, rpy_from_matrix
from twin.workspace import checked_commands, commands_for_poses, layer_poses

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def polisher():
    nominal = Mechanism.from_xml(ROOT / "models/polisher.xml")
    params = load_parameter_set(ROOT / "models/polisher.params.toml", nominal.model)
    model = CalibrationModel(nominal, params)
    poses = layer_poses(nominal, [0.03], 3, (0.2, 0.2))
    rng = np.random.default_rng(5)
    base = np.zeros(len(params))
    base[rng.choice(len(params), 4, replace=False)] = rng.uniform(-2e-3, 2e-3, 4)
    columns = np.sort(rng.choice(len(params), 12, replace=False))
    return model, base, poses, columns, rng


def _per_pose(model, base, delta, columns, poses):
    """Eq. (16) pose by pose: inverse kinematics, B, corrected pose, inverse kinematics."""
    mech = model.mechanism(base)
    out, q = [], None
    for pose in poses:
        sol = inverse(mech, pose, start=q)
        twist = tool_twist_jacobian(mech, model.params, base, sol.qpos)[:, columns] @ delta
        r_cmd = rpy_from_matrix(matrix_from_rotvec(-twist[3:]) @ matrix_from_rpy(pose[3:]))
        corrected = np.concatenate([pose[:3] - twist[:3], r_cmd])
        out.append(inverse(mech, corrected, start=sol.qpos).actuators)
        q = sol.qpos
    return np.array(out)


def test_prepared_compensation_equals_the_per_pose_procedure(polisher):
    model, base, poses, columns, rng = polisher
    prepared = TwistCompensation.prepare(model, base, poses)
    for _ in range(2):  # two estimates from one preparation
        delta = rng.uniform(-1e-3, 1e-3, len(columns))
        expected = _per_pose(model, base, delta, columns, poses)
        np.testing.assert_allclose(prepared.commands(delta, columns), expected, atol=1e-12)
        np.testing.assert_allclose(
            twist_compensated_commands(model, base, delta, columns, poses), expected, atol=1e-12
        )
        assert np.abs(expected - prepared.commands(0 * delta, columns)).max() > 1e-6


def test_zero_estimate_gives_the_controllers_own_commands(polisher):
    model, base, poses, columns, _ = polisher
    prepared = TwistCompensation.prepare(model, base, poses)
    plain = np.array(
        [
            inverse(model.mechanism(base), p, start=q).actuators
            for p, q in zip(poses, prepared.qpos, strict=True)
        ]
    )
    np.testing.assert_allclose(
        prepared.commands(np.zeros(len(columns)), columns), plain, atol=1e-12
    )


def test_prepared_inverse_kinematics_are_the_controllers_commands(polisher):
    """liu_vs_ols takes the coarse stage's commands from the preparation: they must be
    commands_for_poses' own, bit for bit, and pass its checks (checked_commands)."""
    model, base, poses, _, _ = polisher
    mech = model.mechanism(base)
    prepared = TwistCompensation.prepare(model, base, poses)
    from_prep = checked_commands(mech, poses, prepared.qpos[:, mech.actuator_qpos])
    np.testing.assert_array_equal(from_prep, commands_for_poses(mech, poses))
    far = np.array(poses)
    far[2, 0] = 10.0  # 10 m: outside the box
    with pytest.raises(WorkspaceError, match="pose 2"):
        checked_commands(mech, far, from_prep)


def test_poses_corrected_at_once_equal_pose_by_pose():
    """Bitwise: the correction of Eq. (16) on whole arrays against each pose's own."""
    from calib.compensate.compensation import corrected_poses

    rng = np.random.default_rng(8)
    for n in (1, 9, 98):
        poses = np.hstack([rng.uniform(-0.3, 0.3, (n, 3)), rng.uniform(-0.4, 0.4, (n, 3))])
        poses[: n // 2, 3:] = 0.0  # the layers' poses: no rotation
        twists = rng.normal(0.0, 1e-4, (n, 6))
        expected = [
            np.concatenate(
                [
                    p[:3] - t[:3],
                    rpy_from_matrix(matrix_from_rotvec(-t[3:]) @ matrix_from_rpy(p[3:])),
                ]
            )
            for p, t in zip(poses, twists, strict=True)
        ]
        np.testing.assert_array_equal(corrected_poses(poses, twists), np.array(expected))


def test_compensation_starts_from_the_models_own_solves_of_the_same_poses(polisher):
    """The fine plan's inverse kinematics kept by the model (CalibrationModel.commands_for_poses)
    is what the compensation's preparation would solve again: bitwise the same, and only
    for the same values and poses."""
    model, base, poses, columns, rng = polisher
    fresh = CalibrationModel(model.nominal, model.params)
    alone = TwistCompensation.prepare(fresh, base, poses)  # nothing kept: solved here
    commands = fresh.commands_for_poses(base, poses)
    np.testing.assert_array_equal(commands, commands_for_poses(fresh.mechanism(base), poses))
    np.testing.assert_array_equal(fresh.solved_configurations(base, poses), alone.qpos)
    assert fresh.solved_configurations(base + 1e-9, poses) is None
    assert fresh.solved_configurations(base, poses[:-1]) is None
    kept = TwistCompensation.prepare(fresh, base, poses)
    np.testing.assert_array_equal(kept.qpos, alone.qpos)
    np.testing.assert_array_equal(kept.twist_jacobians, alone.twist_jacobians)
    delta = rng.uniform(-1e-3, 1e-3, len(columns))
    np.testing.assert_array_equal(kept.commands(delta, columns), alone.commands(delta, columns))
