"""The batched tool-twist Jacobian equals the per-pose one on every kind of machine, for an
error model's parameters and for the actuators' joint values alike."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import twin.kinematics.sensitivity_batch as sensitivity_batch
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.batch import forward_batch
from twin.kinematics.inverse_batch import actuator_joint_parameters, actuator_twist_jacobians
from twin.kinematics.sensitivity import tool_twist_jacobian
from twin.kinematics.sensitivity_batch import JacobianPlan, tool_twist_jacobian_batch
from twin.kinematics.structure import fast_kinematics
from twin.mechanism import Mechanism
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent
MACHINES = ["hexapod_rrrprr", "polisher", "arm6r"]


def _machine(name: str, n: int, seed: int):
    """Nominal machine, its error model, values, the injected machine and n closed poses."""
    nominal = Mechanism.from_xml(ROOT / f"models/{name}.xml")
    params = load_parameter_set(ROOT / f"models/{name}.params.toml", nominal.model)
    rng = np.random.default_rng(seed)
    values = rng.uniform(-1e-3, 1e-3, len(params))
    mech = nominal.with_model(params.inject(nominal.model, values))
    if nominal.is_serial:
        lo, hi = nominal.actuator_range.T
        commands = rng.uniform(0.5 * lo, 0.5 * hi, (n, nominal.n_actuators))
    else:
        _, commands = random_poses(nominal, n, rng)
    return nominal, params, values, mech, forward_batch(mech, commands).qpos


def _assert_equal(batch: np.ndarray, per_pose: np.ndarray) -> None:
    scale = np.abs(per_pose).max()
    assert scale > 0.1  # not a vacuous comparison
    np.testing.assert_allclose(batch, per_pose, rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("name", MACHINES)
def test_batch_equals_per_pose(name):
    nominal, params, values, mech, qpos = _machine(name, 20, 0)
    per_pose = np.array([tool_twist_jacobian(mech, params, values, q) for q in qpos])
    batch = tool_twist_jacobian_batch(
        mech, params, values, qpos, JacobianPlan.for_mechanism(nominal)
    )
    assert batch.shape == per_pose.shape == (20, 6, len(params))
    _assert_equal(batch, per_pose)
    assert np.abs(per_pose[:, 3:]).max() > 0.1  # the angular rows are compared too
    np.testing.assert_array_equal(tool_twist_jacobian_batch(mech, params, values, qpos), batch)


@pytest.mark.parametrize("name", MACHINES)
def test_actuator_joints_equal_per_pose(name):
    """The actuators' joint-zero parameters (inverse kinematics' chord Jacobian)."""
    _, _, _, mech, qpos = _machine(name, 12, 2)
    params = actuator_joint_parameters(mech)
    zero = np.zeros(len(params))
    per_pose = np.array([tool_twist_jacobian(mech, params, zero, q) for q in qpos])
    _assert_equal(actuator_twist_jacobians(mech, qpos), per_pose)
    _assert_equal(actuator_twist_jacobians(mech, qpos[0]), per_pose[:1])


def test_chunks_join_in_pose_order(monkeypatch):
    import twin.kinematics.sensitivity_compiled as sensitivity_compiled

    _, params, values, mech, qpos = _machine("hexapod_rrrprr", 10, 3)
    whole = tool_twist_jacobian_batch(mech, params, values, qpos)
    # the compiled kernel's poses on three threads: every bit the same
    monkeypatch.setattr(sensitivity_compiled, "PARALLEL_MIN", 1)
    monkeypatch.setattr(sensitivity_compiled, "processors", lambda: 3)
    np.testing.assert_array_equal(tool_twist_jacobian_batch(mech, params, values, qpos), whole)
    # the numpy path's chunks of poses: the same to round-off (a chunk of one pose may take
    # another einsum path)
    monkeypatch.setattr(sensitivity_batch, "COMPILED", False)
    monkeypatch.setattr(sensitivity_batch, "CHUNK", 3)
    _assert_equal(tool_twist_jacobian_batch(mech, params, values, qpos), whole)
    assert tool_twist_jacobian_batch(mech, params, values, qpos[:0]).shape == (0, 6, len(params))


def test_least_squares_closure_equals_per_pose():
    """A closure with more equations than free dofs (a planar four-bar closed by a spherical
    connect; the tool on the coupler, which the rocker's joint does not move): the
    least-squares path."""
    from tests.test_kinematics_fast import four_bar_with_errors

    params, values, mech, qpos = four_bar_with_errors()
    assert not fast_kinematics(mech).closure.square
    per_pose = np.array([tool_twist_jacobian(mech, params, values, q) for q in qpos])
    _assert_equal(tool_twist_jacobian_batch(mech, params, values, qpos), per_pose)
    acts = actuator_joint_parameters(mech)
    zero = np.zeros(len(acts))
    _assert_equal(
        actuator_twist_jacobians(mech, qpos),
        np.array([tool_twist_jacobian(mech, acts, zero, q) for q in qpos]),
    )


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher"])
def test_adjoint_with_static_pivots_refused_equals_per_pose(name, monkeypatch):
    """Every static pivot refused (Householder in the adjoint solve, as for an ill-conditioned
    pose): the Jacobian stays the per-pose one."""
    import twin.kinematics.reduced as kinematics_reduced
    import twin.kinematics.sensitivity_batch as sensitivity_batch
    import twin.kinematics.small_systems as small_systems

    _, params, values, mech, qpos = _machine(name, 8, 4)
    per_pose = np.array([tool_twist_jacobian(mech, params, values, q) for q in qpos])
    static = small_systems.eliminate_static
    calls = []

    def refuse(mat, k, threshold=small_systems.THRESHOLD):
        calls.append(mat.shape)
        return static(mat, k, threshold) & False

    monkeypatch.setattr(kinematics_reduced, "eliminate_static", refuse)
    monkeypatch.setattr(small_systems, "eliminate_static", refuse)
    monkeypatch.setattr(sensitivity_batch, "COMPILED", False)  # the numpy adjoint solve
    _assert_equal(tool_twist_jacobian_batch(mech, params, values, qpos), per_pose)
    assert calls
