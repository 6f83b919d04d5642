"""The batched identification Jacobian equals the per-pose one on every kind of machine."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.batch import forward_batch
from twin.kinematics.sensitivity import target_jacobian
from twin.kinematics.sensitivity_batch import JacobianPlan, target_jacobian_batch
from twin.mechanism import Mechanism
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent


MACHINES = ["hexapod_rrrprr", "polisher", "arm6r_3targets"]


def _machine(name: str, n: int, seed: int, spread: float, reach: float):
    """Nominal machine, error model, values uniform in +-spread, the injected machine and n
    closed poses (a serial arm's commands uniform over ``reach`` of each range)."""
    nominal = Mechanism.from_xml(ROOT / f"models/{name}.xml")
    params = load_parameter_set(ROOT / f"models/{name}.params.toml", nominal.model)
    rng = np.random.default_rng(seed)
    values = rng.uniform(-spread, spread, len(params))
    mech = nominal.with_model(params.inject(nominal.model, values))
    if nominal.is_serial:
        lo, hi = nominal.actuator_range.T
        commands = rng.uniform(reach * lo, reach * hi, (n, nominal.n_actuators))
    else:
        _, commands = random_poses(nominal, n, rng)
    return nominal, params, values, mech, forward_batch(mech, commands).qpos


@pytest.mark.parametrize("name", MACHINES)
def test_batch_equals_per_pose(name):
    nominal, params, values, mech, qpos = _machine(name, 20, 0, 1e-3, 0.5)
    per_pose = np.vstack([target_jacobian(mech, params, values, q) for q in qpos])
    batch = target_jacobian_batch(mech, params, values, qpos, JacobianPlan.for_mechanism(nominal))
    assert batch.shape == per_pose.shape == (20 * nominal.n_targets * 3, len(params))
    np.testing.assert_allclose(batch, per_pose, rtol=0, atol=1e-12)
    assert np.abs(per_pose).max() > 0.1  # not a vacuous comparison


@pytest.mark.parametrize("name", MACHINES)
def test_compiled_kernel_equals_numpy_path(name, monkeypatch):
    """The compiled kernel (frames, screws, explicit and implicit terms pose by pose) and
    the numpy path (arrays over poses) give one Jacobian to round-off."""
    import twin.kinematics.sensitivity_batch as sensitivity_batch

    _, params, values, mech, qpos = _machine(name, 70, 5, 2e-3, 0.8)
    compiled = target_jacobian_batch(mech, params, values, qpos)
    monkeypatch.setattr(sensitivity_batch, "COMPILED", False)
    numpy_path = target_jacobian_batch(mech, params, values, qpos)
    scale = np.abs(numpy_path).max()
    assert scale > 0.1
    np.testing.assert_allclose(compiled, numpy_path, rtol=0, atol=1e-13 * scale)


def test_least_squares_closure_batch_equals_per_pose():
    """A closure with more equations than free dofs (a planar four-bar closed by a spherical
    connect): the batched Jacobian's least-squares path."""
    from tests.test_kinematics_fast import four_bar_with_errors

    params, values, mech, qpos = four_bar_with_errors()
    per_pose = np.vstack([target_jacobian(mech, params, values, q) for q in qpos])
    batch = target_jacobian_batch(mech, params, values, qpos)
    np.testing.assert_allclose(batch, per_pose, rtol=0, atol=1e-12)
    assert np.abs(per_pose).max() > 0.1


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher"])
@pytest.mark.parametrize("refused", ["every", "alternate"])
def test_adjoint_with_static_pivots_refused_equals_per_pose(name, refused, monkeypatch):
    """Poses whose static pivots fail the threshold test (an ill-conditioned closure system,
    or one far from the home configuration the pivots were chosen at) go through Householder
    in the adjoint solve, for the closures' eliminations and for the transposed reduced
    system: the Jacobian stays the per-pose one. No pose within the machines' strokes is
    ill-conditioned enough to refuse a pivot, so the refusal is forced: for every system, or
    for every other one (static and Householder systems side by side in one batch)."""
    import twin.kinematics.reduced as kinematics_reduced
    import twin.kinematics.sensitivity_batch as sensitivity_batch
    import twin.kinematics.small_systems as small_systems

    nominal = Mechanism.from_xml(ROOT / f"models/{name}.xml")
    params = load_parameter_set(ROOT / f"models/{name}.params.toml", nominal.model)
    rng = np.random.default_rng(1)
    values = rng.uniform(-1e-3, 1e-3, len(params))
    mech = nominal.with_model(params.inject(nominal.model, values))
    _, commands = random_poses(nominal, 12, rng)
    qpos = forward_batch(mech, commands).qpos
    per_pose = np.vstack([target_jacobian(mech, params, values, q) for q in qpos])
    static = small_systems.eliminate_static
    calls = []

    def refuse(mat, k, threshold=small_systems.THRESHOLD):
        ok = static(mat, k, threshold)
        calls.append(mat.shape)
        return ok & (np.arange(ok.size) % 2 == 1) if refused == "alternate" else ok & False

    monkeypatch.setattr(kinematics_reduced, "eliminate_static", refuse)
    monkeypatch.setattr(small_systems, "eliminate_static", refuse)
    monkeypatch.setattr(sensitivity_batch, "COMPILED", False)  # the numpy adjoint solve
    batch = target_jacobian_batch(mech, params, values, qpos, JacobianPlan.for_mechanism(nominal))
    s = len(_closure(nominal).shared)
    assert (s, s + 3 * nominal.n_targets, len(qpos)) in calls  # the reduced system too
    np.testing.assert_allclose(batch, per_pose, rtol=0, atol=1e-12)
    assert np.abs(per_pose).max() > 0.1


def _closure(mech: Mechanism):
    from twin.kinematics.structure import fast_kinematics

    return fast_kinematics(mech).closure
