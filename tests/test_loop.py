"""The loop after a diagnosis: effect as a command correction, nonlinear refit, compensation."""

from __future__ import annotations

import numpy as np
import pytest

from calib.fit.model import CalibrationModel
from calib.loop.compensation import invert_correction, loop_commands
from calib.loop.effect import diagnosed_correction
from calib.loop.fit import fit_with_effect
from calib.two_step.nominal import nominal_targets
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.workspace import commands_for_poses, layer_poses


@pytest.fixture(scope="module")
def polisher():
    mech = Mechanism.from_xml("models/polisher.xml")
    params = load_parameter_set("models/polisher.params.toml", mech.model)
    return CalibrationModel(mech, params)


def _plan(model: CalibrationModel) -> np.ndarray:
    return layer_poses(model.nominal, [0.06, -0.06], 4, (0.25, 0.25))


def _true_effect() -> dict[str, np.ndarray]:
    # a gain error of each actuator (ppm scale) and a half play per actuator (backlash)
    gain = np.array([80e-6, -50e-6, 30e-6, 200e-6, -150e-6, 100e-6])
    play = np.array([4e-6, 3e-6, 5e-6, 1.2e-4, 0.8e-4, 1.0e-4])
    return {"gain_error": gain, "backlash": play}


def test_correction_names_and_offsets(polisher):
    corr = diagnosed_correction(polisher, np.zeros(polisher.n_parameters), _true_effect())
    assert corr.n_coefficients == 12
    assert corr.names[0].startswith("gain_error.") and corr.names[6].startswith("backlash.")
    cmds = commands_for_poses(polisher.nominal, _plan(polisher))
    off = corr.offsets(cmds, np.arange(len(cmds)))
    gain = _true_effect()["gain_error"]
    play = _true_effect()["backlash"]
    # the offset is the gain times the command, minus the half play in the approach direction
    prev = np.vstack([polisher.nominal.home_qpos[polisher.nominal.actuator_qpos], cmds[:-1]])
    expected = cmds * gain - play * np.sign(cmds - prev)
    np.testing.assert_allclose(off, expected, rtol=0, atol=1e-15)


def test_noise_free_exact_recovery_of_an_actuator_correction(polisher):
    model = polisher
    names = model.params.names
    encoder = np.flatnonzero([n.endswith(".encoder") for n in names])
    x_true = np.zeros(model.n_parameters)
    x_true[encoder] = np.array([1.5e-3, -2.0e-3, 0.8e-3, 1e-3, -1.5e-3, 0.7e-3])
    truth = _true_effect()
    cmds = commands_for_poses(model.nominal, _plan(model))
    order = np.arange(len(cmds))
    true_corr = diagnosed_correction(model, np.zeros(model.n_parameters), truth)
    measured = model.predict(x_true, true_corr.joints(cmds, order)).targets
    start = true_corr.with_theta(np.zeros(true_corr.n_coefficients))
    fit = fit_with_effect(
        model, np.zeros(model.n_parameters), encoder, start, cmds, order, measured
    )
    assert fit.converged
    np.testing.assert_allclose(fit.values[encoder], x_true[encoder], rtol=0, atol=1e-10)
    np.testing.assert_allclose(fit.correction.theta, true_corr.theta, rtol=1e-6, atol=1e-12)
    assert fit.residual_rms_3d_m < 1e-10


def test_compensation_round_trip(polisher):
    model = polisher
    values = np.zeros(model.n_parameters)
    values[np.flatnonzero([n.endswith(".encoder") for n in model.params.names])] = 1e-3
    corr = diagnosed_correction(model, values, _true_effect())
    poses = layer_poses(model.nominal, [0.0], 3, (0.2, 0.2))
    order = np.arange(len(poses)) + 100
    out = loop_commands(model, values, corr, poses, order)
    # the corrected model at the commands reaches the joint values of the exact IK ...
    np.testing.assert_allclose(corr.joints(out.commands, order), out.joints, rtol=0, atol=1e-12)
    # ... and so the poses asked for
    reached = model.predict(values, corr.joints(out.commands, order)).targets
    wanted = nominal_targets(model.mechanism(values), poses)
    assert np.max(np.abs(reached - wanted)) < 1e-9
    # the correction is not empty: the commands differ from the uncorrected ones
    assert np.max(np.abs(out.commands - out.joints)) > 1e-6


def test_fixed_point_refuses_a_correction_steeper_than_the_command(polisher):
    corr = diagnosed_correction(
        polisher, np.zeros(polisher.n_parameters), {"gain_error": np.full(6, -1.5)}
    )
    q = commands_for_poses(polisher.nominal, _plan(polisher))
    from calib.exceptions import ConvergenceError

    with pytest.raises(ConvergenceError, match="did not settle"):
        invert_correction(corr, q, np.arange(len(q)))


def test_column_jacobian_equals_the_whole_one_and_the_actuators(polisher):
    """The loop's Jacobian in one pass (calib.fit.model.ColumnJacobian) against the whole
    identification Jacobian's columns and the per-actuator one, at geometry where the body
    rotations left out of the columns are not zero (their rotation vectors compose)."""
    from calib.diagnosis.apply import actuator_jacobians_batch
    from calib.diagnosis.context import actuator_offsets
    from calib.fit.model import ColumnJacobian
    from twin.parameters import KINDS, Parameter, ParameterSet

    model = polisher
    params = model.params
    rng = np.random.default_rng(4)
    values = rng.uniform(-3e-4, 3e-4, model.n_parameters)
    rot = np.flatnonzero(params.kind == KINDS.index("body_rot"))
    body = params.body[rot[0]]
    companions = rot[params.body[rot] == body]
    assert len(companions) > 1  # a body with several rotations, one of them chosen
    cols = np.sort(np.concatenate([companions[:1], rng.choice(model.n_parameters, 20, False)]))
    cols = np.unique(cols[~np.isin(cols, companions[1:])])
    cmds = commands_for_poses(model.nominal, _plan(model))
    pred = model.predict(values, cmds)
    offsets = actuator_offsets(model)
    got = ColumnJacobian.of(model, cols, offsets)(values, pred)
    whole = model.jacobian(values, pred)[:, cols]
    act = actuator_jacobians_batch(model, values, pred.qpos).reshape(len(whole), -1)
    expected = np.hstack([whole, act])
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    alone = ColumnJacobian.of(model, cols)(values, pred)
    np.testing.assert_allclose(alone, whole, rtol=0, atol=1e-12 * np.abs(whole).max())
    # extra parameters named as some of the model's: kept apart
    clash = ParameterSet(
        [Parameter(params.names[0], p.kind, p.element) for p in offsets.parameters[:1]],
        model.nominal.model,
    )
    same = ColumnJacobian.of(model, cols, clash)(values, pred)
    np.testing.assert_array_equal(same[:, -1], got[:, len(cols)])
