"""The batched identification Jacobian equals the per-pose one on every kind of machine."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.kinematics_batch import forward_batch
from twin.mechanism import Mechanism
from twin.parameter_file import load_parameter_set
from twin.sensitivity import target_jacobian
from twin.sensitivity_batch import JacobianPlan, target_jacobian_batch
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher", "arm6r_3targets"])
def test_batch_equals_per_pose(name):
    nominal = Mechanism.from_xml(ROOT / f"models/{name}.xml")
    params = load_parameter_set(ROOT / f"models/{name}.params.toml", nominal.model)
    rng = np.random.default_rng(0)
    values = rng.uniform(-1e-3, 1e-3, len(params))
    mech = nominal.with_model(params.inject(nominal.model, values))
    if nominal.is_serial:
        lo, hi = nominal.actuator_range.T
        commands = rng.uniform(0.5 * lo, 0.5 * hi, (20, nominal.n_actuators))
    else:
        _, commands = random_poses(nominal, 20, rng)
    qpos = forward_batch(mech, commands).qpos
    per_pose = np.vstack([target_jacobian(mech, params, values, q) for q in qpos])
    batch = target_jacobian_batch(mech, params, values, qpos, JacobianPlan.for_mechanism(nominal))
    assert batch.shape == per_pose.shape == (20 * nominal.n_targets * 3, len(params))
    np.testing.assert_allclose(batch, per_pose, rtol=0, atol=1e-12)
    assert np.abs(per_pose).max() > 0.1  # not a vacuous comparison


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher"])
def test_first_order_start_of_the_closure_solve(name):
    """The linearisation at a solution moves it to within |d|^2 of the solution at values
    d away, and a prediction started there equals one solved from scratch."""
    from calib.model import CalibrationModel
    from twin.sensitivity_batch import target_jacobian_linearised

    nominal = Mechanism.from_xml(ROOT / f"models/{name}.xml")
    params = load_parameter_set(ROOT / f"models/{name}.params.toml", nominal.model)
    rng = np.random.default_rng(3)
    values = rng.uniform(-1e-3, 1e-3, len(params))
    _, commands = random_poses(nominal, 12, rng)
    mech = nominal.with_model(params.inject(nominal.model, values))
    q0 = forward_batch(mech, commands).qpos
    _, lin = target_jacobian_linearised(mech, params, values, q0)
    direction = rng.uniform(-1, 1, len(params))
    errors = []
    for size in (1e-4, 1e-5):
        moved = values + size * direction
        q1 = forward_batch(nominal.with_model(params.inject(nominal.model, moved)), commands).qpos
        errors.append(np.max(np.abs(lin.start(moved) - q1)))
        assert errors[-1] < 3e-3 * np.max(np.abs(q0 - q1))
    assert errors[1] < 0.02 * errors[0]  # second order: a tenth of the step, a hundredth
    model = CalibrationModel(nominal, params)
    pred = model.predict(values, commands)
    model.jacobian(values, pred)  # linearised here
    warm = model.predict(moved, commands)
    cold = CalibrationModel(nominal, params).predict(moved, commands)
    np.testing.assert_allclose(warm.targets, cold.targets, rtol=0, atol=1e-12)


def test_least_squares_closure_batch_equals_per_pose():
    """A closure with more equations than free dofs (a planar four-bar closed by a spherical
    connect): the batched Jacobian's least-squares path and its first-order start."""
    from tests.test_kinematics_fast import FOUR_BAR
    from twin.parameters import Parameter, ParameterSet
    from twin.sensitivity_batch import target_jacobian_linearised

    nominal = Mechanism.from_xml_string(FOUR_BAR)
    params = ParameterSet(
        [
            Parameter("rocker_x", "body_pos", "rocker", (1.0, 0.0, 0.0)),
            Parameter("rocker_y", "body_pos", "rocker", (0.0, 1.0, 0.0)),
            Parameter("coupler_rz", "body_rot", "coupler", (0.0, 0.0, 1.0)),
            Parameter("end_y", "site_pos", "end", (0.0, 1.0, 0.0)),
            Parameter("j2_zero", "joint_zero", "j2"),
        ],
        nominal.model,
    )
    values = np.array([1e-3, -2e-3, 3e-3, 1e-3, -2e-3])
    mech = nominal.with_model(params.inject(nominal.model, values))
    commands = np.linspace(-0.4, 0.4, 9)[:, None]
    qpos = forward_batch(mech, commands).qpos
    per_pose = np.vstack([target_jacobian(mech, params, values, q) for q in qpos])
    batch, lin = target_jacobian_linearised(mech, params, values, qpos)
    np.testing.assert_allclose(batch, per_pose, rtol=0, atol=1e-12)
    assert np.abs(per_pose).max() > 0.1
    moved = values + 1e-5
    q1 = forward_batch(nominal.with_model(params.inject(nominal.model, moved)), commands).qpos
    assert np.max(np.abs(lin.start(moved) - q1)) < 1e-3 * np.max(np.abs(qpos - q1))
