"""The error-model kind ``actuator_gain``: a scale per actuator, in the calibration model.

A gain ``g`` makes the joint take ``q0 + (c - q0)(1 + g)`` for the command ``c`` (``q0`` the
joint's zero in the model at the current values). The checks: the full Jacobian (geometry,
joint zeros of gained actuators, gains) against finite differences of the prediction on a
serial arm and on the closed-chain hexapod; noise-free exact recovery of geometry plus gains
from twin readings whose truth carries the twin's own gain effect (the calibration only gets
the readings); the error-model file with the kind (ppm in files) and its errors; inverse
kinematics that returns commands through the gains; the twin's geometric Jacobians refusing
the kind instead of giving it a column it does not have.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fd_support import central_differences

from calib.analysis.identifiability import analyse
from calib.compensate.compensation import compensated_commands
from calib.fit.identification import identify
from calib.fit.model import CalibrationModel, ColumnJacobian
from calib.fit.observations import Observations
from twin.effects.actuator_gain import ActuatorGain
from twin.exceptions import ParameterError
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.kinematics.batch import forward_batch
from twin.kinematics.inverse_batch import actuator_joint_parameters
from twin.kinematics.sensitivity_batch import target_jacobian_batch
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.parameters import KINDS, Parameter, ParameterSet
from twin.rotations import rotvec_from_matrix
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import commands_for_poses, random_poses

MODELS = Path(__file__).resolve().parents[1] / "models"
GAIN_PPM = 300.0  # bound of the drawn gains (uncalibrated drives: 100-500 ppm)
EXACT = Tracker(noise=TrackerNoise.none())


def _gain_toml(machine: str, mech: Mechanism, tmp_path: Path) -> Path:
    """The shipped error model of ``machine`` plus one gain per actuator, as a user writes it."""
    text = (MODELS / f"{machine}.params.toml").read_text()
    for a in mech.actuator_names:
        text += f'\n[[parameter]]\nname = "{a}.gain"\nkind = "actuator_gain"\nelement = "{a}"\n'
    path = tmp_path / f"{machine}_gains.params.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def arm() -> Mechanism:
    return Mechanism.from_xml(MODELS / "arm6r.xml")


@pytest.fixture(scope="module")
def hexapod() -> Mechanism:
    return Mechanism.from_xml(MODELS / "hexapod_rrrprr.xml")


def _machine(name: str, request, tmp_path_factory) -> tuple[Mechanism, ParameterSet, np.ndarray]:
    """The machine, its error model with gains (read from a file) and 30 commands."""
    mech = request.getfixturevalue(name)
    params = load_parameter_set(
        _gain_toml(mech.name, mech, tmp_path_factory.mktemp("p")), mech.model
    )
    rng = np.random.default_rng(11)
    if mech.is_serial:  # joints spread over most of their ranges
        lo, hi = mech.actuator_range.T
        commands = rng.uniform(0.7 * lo, 0.7 * hi, (30, mech.n_actuators))
    else:
        commands = random_poses(mech, 30, rng)[1]
    return mech, params, commands


def _draw(params: ParameterSet, rng: np.random.Generator) -> np.ndarray:
    """Geometric errors (0.2 mm, 0.05 deg) and gains (GAIN_PPM), SI."""
    scale = np.where(params.is_angle, np.radians(0.05), 2e-4)
    scale = np.where(params.is_gain, GAIN_PPM * 1e-6, scale)
    return rng.uniform(-1.0, 1.0, len(params)) * scale


def _fd_jacobian(model: CalibrationModel, x: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """Central differences of the predicted targets; steps of 1e-6 (m, rad) and 10 ppm
    (the closure solve stops near 1e-13 m: a smaller step would measure that)."""
    steps = np.where(model.params.is_gain, 1e-5, 1e-6)
    return central_differences(model, x, commands, steps)


@pytest.mark.parametrize("name", ["arm", "hexapod"])
def test_jacobian_with_gains_against_finite_differences(name, request, tmp_path_factory):
    mech, params, commands = _machine(name, request, tmp_path_factory)
    model = CalibrationModel(mech, params)
    x = _draw(params, np.random.default_rng(2))
    c = commands[:4]
    jac = model.jacobian(x, model.predict(x, c))
    fd = _fd_jacobian(model, x, c)
    rel = np.abs(fd - jac).max(axis=0) / np.linalg.norm(jac, axis=0)
    assert np.all(np.linalg.norm(jac[:, params.is_gain], axis=0) > 1e-3)  # gains move targets
    assert np.max(rel) < 1e-6, params.names[int(np.argmax(rel))]
    # a joint zero of a gained actuator is (1 + g) times its geometric column: the FD check
    # sees the difference where the model has one (the arm's link<i>.theta)
    zeros = [k for k, p in enumerate(params.parameters) if p.kind == "joint_zero"]
    if zeros:
        geometric = CalibrationModel(
            mech,
            ParameterSet([p for p in params.parameters if p.kind != "actuator_gain"], mech.model),
        )
        xg = x[~params.is_gain]
        plain = geometric.jacobian(xg, geometric.predict(xg, model.joints_for_commands(x, c)))
        k_geo = [geometric.params.index(params.names[k]) for k in zeros]
        gap = np.abs(plain[:, k_geo] - jac[:, zeros]).max(axis=0)
        assert np.all(gap > 1e3 * np.abs(fd - jac)[:, zeros].max(axis=0))


def test_column_jacobian_with_gains_and_command_columns(hexapod, arm, tmp_path):
    """ColumnJacobian (the loop's and the diagnosis's one pass) on a model with gains: chosen
    columns as the model's, extra actuator-joint columns as d(targets)/d(command), an extra
    gain as the model's gain column."""
    for mech in (arm, hexapod):
        params = load_parameter_set(_gain_toml(mech.name, mech, tmp_path), mech.model)
        model = CalibrationModel(mech, params)
        rng = np.random.default_rng(5)
        x = _draw(params, rng)
        lo, hi = mech.actuator_range.T
        c = (
            rng.uniform(0.5 * lo, 0.5 * hi, (3, mech.n_actuators))
            if mech.is_serial
            else random_poses(mech, 3, rng)[1]
        )
        pred = model.predict(x, c)
        full = model.jacobian(x, pred)
        cols = np.array([len(params) - 1, 0, 3, len(params) - 4, 1])
        a = mech.actuator_names[2]
        joints = actuator_joint_parameters(mech).parameters
        extra = ParameterSet([*joints, Parameter(f"{a}.gain", "actuator_gain", a)], mech.model)
        got = ColumnJacobian.of(model, cols, extra)(x, pred)
        np.testing.assert_allclose(got[:, : len(cols)], full[:, cols], rtol=0, atol=1e-13)
        np.testing.assert_allclose(
            got[:, -1], full[:, params.index(f"{a}.gain")], rtol=0, atol=1e-13
        )
        h = 1e-7
        for i in range(mech.n_actuators):
            dc = np.zeros_like(c)
            dc[:, i] = h
            fd = (model.predict(x, c + dc).targets - model.predict(x, c - dc).targets) / (2 * h)
            err = np.abs(fd.reshape(-1) - got[:, len(cols) + i]).max()
            assert err < 1e-6 * np.linalg.norm(got[:, len(cols) + i])


@pytest.mark.parametrize("name", ["arm", "hexapod"])
def test_noise_free_recovery_of_geometry_and_gains(name, request, tmp_path_factory):
    """Twin readings of a truth with geometric errors and the twin's ActuatorGain effect: the
    calibration, which sees only the commands and readings, gives both back to round-off."""
    mech, params, commands = _machine(name, request, tmp_path_factory)
    model = CalibrationModel(mech, params)
    zero = np.zeros(len(params))
    start = analyse(model.jacobian(zero, model.predict(zero, commands)), params.names)
    free = np.array([n in start.identifiable for n in params.names])
    assert np.all(free[params.is_gain])  # every gain is identifiable on both machines
    truth = np.where(free, _draw(params, np.random.default_rng(7)), 0.0)
    geometry = ParameterSet(
        [p for p in params.parameters if not p.kind == "actuator_gain"], mech.model
    )
    truth_mech = mech.with_model(geometry.inject(mech.model, truth[~params.is_gain]))
    gains = ActuatorGain(gains_ppm=tuple(truth[params.is_gain] * 1e6))
    readings = measure(truth_mech, commands, EXACT, np.random.default_rng(0), effects=[gains])
    obs = Observations(commands, readings.readings.mean(axis=2))
    res = identify(model, obs, unidentifiable="fix")
    assert res.converged
    assert res.estimated.sum() == free.sum()
    err = np.abs(res.values - truth)
    # of an exactly redundant group identify may fix another member than the truth's zero
    # (the one that keeps the estimates smallest): the geometry agrees with the truth up to
    # the groups' directions, so it is compared where it acts, on the targets
    assert np.max(err[params.is_gain]) * 1e6 < 1e-6  # ppm
    if np.array_equal(res.estimated, free):
        assert np.max(err[~params.is_gain]) < 1e-11  # m, rad
    assert res.residual_rms < 1e-12
    # and the two give the same machine wherever it moves
    other = (commands[:-1] + commands[1:]) / 2  # other poses: strokes are boxes, convex
    got = model.predict(res.values, other).targets
    want = measure(truth_mech, other, EXACT, np.random.default_rng(1), effects=[gains])
    assert np.max(np.abs(got - want.readings.mean(axis=2))) < 1e-11
    # without the gains the same geometry cannot follow these readings
    alone = identify(CalibrationModel(mech, geometry), obs, unidentifiable="fix")
    assert alone.residual_rms > 1e4 * res.residual_rms


def test_commands_for_poses_then_predict(hexapod, tmp_path):
    """Inverse kinematics through the gains returns commands, not joint values: predicting
    them gives the poses back, and the compensation uses them."""
    params = load_parameter_set(_gain_toml("hexapod_rrrprr", hexapod, tmp_path), hexapod.model)
    model = CalibrationModel(hexapod, params)
    x = _draw(params, np.random.default_rng(3))
    poses = random_poses(hexapod, 6, np.random.default_rng(9))[0]
    commands = model.commands_for_poses(x, poses)
    joints = commands_for_poses(model.mechanism(x), poses)  # what the model's joints must take
    zero = model.joint_zeros(x)
    g = x[params.is_gain]
    # the commands are not the joint values: they differ by g (q - q0) / (1 + g), microns
    np.testing.assert_allclose(commands, zero + (joints - zero) / (1 + g), rtol=0, atol=1e-15)
    assert np.min(np.abs(commands - joints).max(axis=0)) > 1e-7
    pred = model.predict(x, commands)
    np.testing.assert_allclose(pred.qpos[:, hexapod.actuator_qpos], joints, rtol=0, atol=1e-15)
    sol = forward_batch(model.mechanism(x), model.joints_for_commands(x, commands))
    np.testing.assert_allclose(sol.tool_position, poses[:, :3], rtol=0, atol=1e-12)
    turned = sol.tool_rotation @ np.transpose(
        forward_batch(model.mechanism(x), joints).tool_rotation, (0, 2, 1)
    )
    assert np.max(np.abs(rotvec_from_matrix(turned))) < 1e-12
    np.testing.assert_array_equal(compensated_commands(model, x, poses), commands)


def test_tool_twist_jacobian_with_gains_against_finite_differences(arm, tmp_path):
    params = load_parameter_set(_gain_toml("arm6r", arm, tmp_path), arm.model)
    model = CalibrationModel(arm, params)
    x = _draw(params, np.random.default_rng(4))
    c = np.random.default_rng(6).uniform(-1.0, 1.0, (3, arm.n_actuators))
    jac = model.tool_twist_jacobian(x, model.predict(x, c).qpos)

    def tool(v: np.ndarray):
        sol = forward_batch(model.mechanism(v), model.joints_for_commands(v, c))
        return sol.tool_position, sol.tool_rotation

    for k in np.flatnonzero(params.is_gain | (params.kind == KINDS.index("joint_zero"))):
        h = 1e-6
        dx = np.zeros(len(x))
        dx[k] = h
        (p1, r1), (p0, r0) = tool(x + dx), tool(x - dx)
        lin = (p1 - p0) / (2 * h)
        ang = rotvec_from_matrix(r1 @ np.transpose(r0, (0, 2, 1))) / (2 * h)
        fd = np.hstack([lin, ang])
        assert np.abs(fd - jac[:, :, k]).max() < 1e-7 * np.abs(jac[:, :, k]).max()


def test_file_units_and_injection(hexapod, tmp_path):
    """Gains are ppm in files and printouts, SI inside; the other kinds keep their units bit for
    bit; injection leaves a gain out (it is no geometry)."""
    params = load_parameter_set(_gain_toml("hexapod_rrrprr", hexapod, tmp_path), hexapod.model)
    base = load_parameter_set(MODELS / "hexapod_rrrprr.params.toml", hexapod.model)
    assert params.names[: len(base)] == base.names and len(params) == len(base) + 6
    assert params.units() == ["m"] * 54 + ["1"] * 6
    assert params.display_units() == ["mm"] * 54 + ["ppm"] * 6
    values = tmp_path / "values.toml"
    values.write_text('unit = "mm"\n[values]\n"leg1.base.dx" = 0.25\n"leg3.gain" = -120.5\n')
    si = load_values(values, params)
    assert si[params.index("leg3.gain")] == -120.5 * 1e-6  # ppm
    assert si[params.index("leg1.base.dx")] == 0.25 * 1e-3  # mm
    x = _draw(params, np.random.default_rng(1))
    np.testing.assert_array_equal(params.to_display(x)[:54], base.to_display(x[:54]))
    np.testing.assert_array_equal(params.to_display(x)[54:], x[54:] * 1e6)
    np.testing.assert_allclose(params.from_display(params.to_display(x)), x, rtol=1e-15, atol=0)
    gains_only = np.where(params.is_gain, x, 0.0)
    injected = params.inject(hexapod.model, gains_only)
    for field in ("body_pos", "body_quat", "site_pos", "qpos0"):
        np.testing.assert_array_equal(getattr(injected, field), getattr(hexapod.model, field))


def test_bad_gain_entries_are_named(hexapod, tmp_path):
    path = tmp_path / "bad.params.toml"
    path.write_text('[[parameter]]\nname = "g3"\nkind = "actuator_gain"\nelement = "leg_3"\n')
    with pytest.raises(
        ParameterError,
        match=r"bad.params.toml.*'g3'.*no actuator named 'leg_3' "
        r"\(did you mean 'leg3'\?\)",
    ):
        load_parameter_set(path, hexapod.model)
    path.write_text('[[parameter]]\nname = "g3"\nkind = "actuator_gian"\nelement = "leg3"\n')
    with pytest.raises(ParameterError, match=r"'actuator_gian' \(did you mean 'actuator_gain'\?\)"):
        load_parameter_set(path, hexapod.model)
    params = ParameterSet([Parameter("g1", "actuator_gain", "leg1")], hexapod.model)
    with pytest.raises(ParameterError, match=r"geometric parameters only.*\['g1'\]"):
        target_jacobian_batch(hexapod, params, np.zeros(1), hexapod.home_qpos[None])
    model = CalibrationModel(hexapod, params)
    with pytest.raises(ParameterError, match=r"actuator 'leg1'.*-1e\+06 ppm"):
        model.predict(np.array([-1.0]), random_poses(hexapod, 1, np.random.default_rng(0))[1])
