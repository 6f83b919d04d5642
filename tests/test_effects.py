"""Physical effects of the truth twin: each against its defining formula or physics."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from twin.effects import Backlash, GravityCompliance, LeadError, ThermalGrowth
from twin.effects.base import apply_actuator_effects
from twin.kinematics.closure import closure_jacobian, update_kinematics
from twin.kinematics.single_pose import forward
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import commands_for_poses, layer_poses

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def polisher() -> Mechanism:
    return Mechanism.from_xml(ROOT / "models/polisher.xml")


@pytest.fixture(scope="module")
def commands(polisher) -> np.ndarray:
    return commands_for_poses(polisher, layer_poses(polisher, [0.0], 3, (0.25, 0.25)))


def test_thermal_growth_is_proportional_to_length_and_temperature(polisher, commands):
    eff = ThermalGrowth(start_K=1.0, rate_K_per_pose=0.5, alpha_per_K=11.5e-6)
    out = eff.apply(polisher, commands, np.arange(len(commands)))
    slide = polisher.actuator_is_slide
    dt = 1.0 + 0.5 * np.arange(len(commands))
    np.testing.assert_allclose(
        out[:, slide], commands[:, slide] * (1 + 11.5e-6 * dt[:, None]), rtol=1e-15
    )
    np.testing.assert_array_equal(out[:, ~slide], commands[:, ~slide])  # wrist angles untouched


def test_lead_error_is_periodic_in_the_screw_position(polisher, commands):
    eff = LeadError(amplitude_m=4e-6, pitch_m=5e-3)
    dev = eff.apply(polisher, commands, np.arange(len(commands))) - commands
    assert np.max(np.abs(dev)) <= 4e-6 + 1e-18
    shifted = commands.copy()
    shifted[:, polisher.actuator_is_slide] += 5e-3  # one lead further: the same error
    dev2 = eff.apply(polisher, shifted, np.arange(len(commands))) - shifted
    np.testing.assert_allclose(dev2, dev, atol=1e-15)


def test_backlash_follows_the_approach_direction(polisher, commands):
    eff = Backlash(play_m=10e-6)
    seq = commands[[4, 0, 8]]  # move around: each actuator goes up or down between poses
    out = eff.apply(polisher, seq, np.arange(3))
    previous = np.vstack([polisher.home_qpos[polisher.actuator_qpos], seq[:-1]])
    expected = seq - 5e-6 * np.sign(seq - previous) * polisher.actuator_is_slide
    np.testing.assert_allclose(out, expected, atol=1e-18)
    # the same poses measured in reverse order are approached from the other side
    reverse = eff.apply(polisher, seq, np.array([2, 1, 0]))
    assert not np.allclose(reverse, out)


def test_gravity_equilibrium_balances_the_load(polisher, commands):
    eff = GravityCompliance(payload_kg=20.0)
    heavy = eff.loaded(polisher)
    sol = forward(heavy, commands[4])
    tau = eff.actuator_forces(heavy, sol.qpos)
    d = heavy.data
    d.qpos[:] = sol.qpos
    d.qvel[:] = 0
    mujoco.mj_forward(heavy.model, d)
    update_kinematics(heavy, sol.qpos)
    jc = closure_jacobian(heavy)
    sel = np.zeros((heavy.n_actuators, heavy.model.nv))
    sel[np.arange(heavy.n_actuators), heavy.actuator_dofs] = 1.0
    lam = np.linalg.lstsq(jc.T, d.qfrc_bias - sel.T @ tau, rcond=None)[0]
    residual = d.qfrc_bias - jc.T @ lam - sel.T @ tau
    assert np.max(np.abs(residual)) < 1e-9 * np.max(np.abs(d.qfrc_bias))
    # the total vertical load the limbs carry is the weight: more payload, more force
    tau_light = eff.actuator_forces(polisher, forward(polisher, commands[4]).qpos)
    assert np.linalg.norm(tau) > np.linalg.norm(tau_light)


def test_gravity_deflection_scales_with_compliance(polisher, commands):
    c = commands[[4]]
    soft = GravityCompliance(stiffness_N_per_m=1e7, payload_kg=20.0).apply(polisher, c, [0]) - c
    stiff = GravityCompliance(stiffness_N_per_m=2e7, payload_kg=20.0).apply(polisher, c, [0]) - c
    slide = polisher.actuator_is_slide
    np.testing.assert_allclose(soft[:, slide], 2 * stiff[:, slide], rtol=1e-3)
    assert np.max(np.abs(soft[:, slide])) > 10e-6  # tens of micrometres: a real effect


def test_measure_applies_effects_in_measurement_order(polisher, commands):
    tracker = Tracker(noise=TrackerNoise.none())
    rng = np.random.default_rng(0)
    plain = measure(polisher, commands, tracker, rng)
    warm = measure(polisher, commands, tracker, rng, effects=[ThermalGrowth(rate_K_per_pose=1.0)])
    moved = np.linalg.norm(warm.true_targets - plain.true_targets, axis=-1).max(axis=1)
    assert moved[0] == 0.0 and np.all(np.diff(moved) > 0)  # drift grows along the sequence
    again = apply_actuator_effects(polisher, [], commands)
    np.testing.assert_array_equal(again, commands)
