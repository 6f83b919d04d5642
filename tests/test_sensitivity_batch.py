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
