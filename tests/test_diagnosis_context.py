"""The diagnosis's sensitivities of a long campaign (all poses at once, the batched adjoint)
equal those of a short one (each pose's Jacobian on its own) on every kind of machine."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import calib.diagnosis.context as context
from calib.fit.model import CalibrationModel
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.workspace import random_commands

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("name", ["arm6r_3targets", "hexapod_rrrprr", "polisher"])
def test_batched_sensitivities_equal_per_pose(name, monkeypatch):
    nominal = Mechanism.from_xml(ROOT / f"models/{name}.xml")
    params = load_parameter_set(ROOT / f"models/{name}.params.toml", nominal.model)
    model = CalibrationModel(nominal, params)
    rng = np.random.default_rng(3)
    values = rng.uniform(-1e-3, 1e-3, len(params))
    commands = random_commands(nominal, 15, 0.7, rng)
    qpos = model.predict(values, commands).qpos
    batched = context.target_jacobian_batch
    calls = []
    monkeypatch.setattr(context, "target_jacobian_batch", lambda *a: calls.append(1) or batched(*a))
    j_one, extra_one = context.sensitivities(model, values, qpos)
    monkeypatch.setattr(context, "PER_POSE_MAX", 10)  # 15 poses: a long campaign
    j_all, extra_all = context.sensitivities(model, values, qpos)
    assert len(calls) == 1  # the second, long, campaign only
    assert j_all.shape == j_one.shape == (15, 3 * nominal.n_targets, nominal.n_actuators)
    scale = np.abs(j_one).max()
    assert scale > 0.1  # not a vacuous comparison
    np.testing.assert_allclose(j_all, j_one, rtol=0, atol=1e-12 * scale)
    assert extra_all.groups == extra_one.groups
    assert any(c.size for c in extra_one.columns.values())
    for g, cols in extra_one.columns.items():
        assert extra_all.columns[g].shape == cols.shape
        np.testing.assert_allclose(extra_all.columns[g], cols, rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("name", ["arm6r_3targets", "hexapod_rrrprr"])
def test_gravity_loads_in_two_processes_are_those_of_one(name, monkeypatch):
    """The loads of a long run's poses, computed in chunks by worker processes, are those of
    one process bit for bit (each pose's arithmetic is the same wherever it runs)."""
    import calib.diagnosis.gravity as gravity
    from common import worker_processes

    nominal = Mechanism.from_xml(ROOT / f"models/{name}.xml")
    rng = np.random.default_rng(5)
    commands = random_commands(nominal, 9, 0.7, rng)
    params = load_parameter_set(ROOT / f"models/{name}.params.toml", nominal.model)
    qpos = CalibrationModel(nominal, params).predict(np.zeros(len(params)), commands).qpos
    used = []
    mapped = worker_processes.map_in_order

    def spied(fn, n_tasks, workers):
        used.append(workers)
        return mapped(fn, n_tasks, workers)

    monkeypatch.setattr(worker_processes, "map_in_order", spied)
    loads = {}
    for workers in ("1", "2"):
        monkeypatch.setenv(worker_processes.ENV_WORKERS, workers)
        loads[workers] = gravity.gravity_loads(nominal, qpos)
    assert used == [1, 2]
    one, two = loads["1"], loads["2"]
    assert np.abs(one.own).max() > 0 and np.abs(one.unit_payload).max() > 0
    np.testing.assert_array_equal(one.own, two.own)
    np.testing.assert_array_equal(one.unit_payload, two.unit_payload)
    assert one.moving_mass_kg == two.moving_mass_kg
