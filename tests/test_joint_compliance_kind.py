"""The error-model kind ``joint_compliance``: joints that yield to their gravity load.

A compliance ``k`` makes the joint settle at ``q = j - k L(q)`` (``j`` the joint value the
command asks, through the gain if any; ``L`` the actuator's gravity load at the pose, from the
calibration's own model: the model's masses plus ``payload_kg`` at the tool, or per kg of a
tool payload on a model without masses). The checks: the Jacobian against finite differences
on the 6R arm (masses defaulted: per kg) and the closed-chain hexapod (prismatic legs), exact
at zero compliance and with the loads held, and the size of the load-derivative terms it
leaves out otherwise; noise-free exact recovery of geometry, gains and compliances from twin
readings whose truth carries the twin's own JointCompliance effect (the calibration only gets
the readings), on a model with declared masses too; inverse kinematics and the compensation
through the compliance; units, files and errors of the kind.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from fd_support import central_differences

import calib.fit.joint_compliance as joint_compliance
import calib.fit.model as calib_model
from calib.analysis.identifiability import analyse
from calib.compensate.compensation import compensated_commands, reachable_compensated_commands
from calib.compensate.poses import solve_each
from calib.fit.identification import identify
from calib.fit.model import CalibrationModel, ColumnJacobian
from calib.fit.observations import Observations
from calib.loop.effect_kinds import compliance_parameters
from twin.effects import ActuatorGain, JointCompliance
from twin.exceptions import ParameterError
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.batch import forward_batch
from twin.kinematics.sensitivity_batch import target_jacobian_batch
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.parameters import Parameter, ParameterSet
from twin.rotations import rpy_from_matrix
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

MODELS = Path(__file__).resolve().parents[1] / "models"
EXACT = Tracker(noise=TrackerNoise.none())


def _inertial(m: re.Match) -> str:
    """The joint's line and an inertial of its link: 7 kg for link 1 down to 2 kg for link 6,
    off the joint's axis except the last one's (a flange's mass is centred)."""
    i = int(m.group(2))
    x = "0" if i == 6 else "0.05"
    return m.group(1) + f'<inertial pos="{x} 0 0.02" mass="{8 - i}" diaginertia="0.01 0.01 0.01"/>'


def _massive_arm() -> Mechanism:
    """The 6R arm with declared masses, one per moving link (the same machine as
    arm6r_3targets, whose error model it takes, weighed)."""
    xml = (MODELS / "arm6r_3targets.xml").read_text()
    xml = re.sub(r'(<joint name="A(\d)"[^>]*/>)', _inertial, xml)
    return Mechanism.from_xml_string(xml)


def _machine(name: str, payload_kg: float | None = None, gains: bool = True):
    """(mechanism, error model + one compliance (+ one gain) per actuator, 30 commands)."""
    if name == "hexapod":
        mech = Mechanism.from_xml(MODELS / "hexapod_rrrprr.xml")
        errors = MODELS / "hexapod_rrrprr.params.toml"
    else:
        mech = _massive_arm() if name == "massive" else Mechanism.from_xml(MODELS / f"{name}.xml")
        errors = MODELS / "arm6r_3targets.params.toml"
    base = load_parameter_set(errors, mech.model)
    names = mech.actuator_names
    extra = [
        Parameter(f"{a}.compliance", "joint_compliance", a, payload_kg=payload_kg) for a in names
    ]
    if gains:
        extra += [Parameter(f"{a}.gain", "actuator_gain", a) for a in names]
    params = ParameterSet([*base.parameters, *extra], mech.model)
    rng = np.random.default_rng(11)
    if mech.is_serial:
        lo, hi = mech.actuator_range.T
        commands = rng.uniform(0.7 * lo, 0.7 * hi, (30, mech.n_actuators))
    else:
        commands = random_poses(mech, 30, rng)[1]
    return mech, params, commands


def _draw(params: ParameterSet, rng: np.random.Generator, compliance: float) -> np.ndarray:
    """Geometry (0.2 mm, 0.05 deg), gains (300 ppm) and compliances (``compliance`` SI,
    half to full), SI."""
    scale = np.where(params.is_angle, np.radians(0.05), 2e-4)
    scale = np.where(params.is_gain, 3e-4, scale)
    x = rng.uniform(-1.0, 1.0, len(params)) * scale
    return np.where(params.is_compliance, compliance * rng.uniform(0.5, 1.0, len(params)), x)


def _fd(model: CalibrationModel, x: np.ndarray, commands: np.ndarray, size: float) -> np.ndarray:
    """Central differences of the predicted targets, step 1e-6 SI (10 ppm for a gain, a
    hundredth of the compliances' ``size`` for a compliance)."""
    steps = np.where(model.params.is_gain, 1e-5, 1e-6)
    steps = np.where(model.params.is_compliance, 1e-2 * size, steps)
    return central_differences(model, x, commands, steps)


def _relative(fd: np.ndarray, jac: np.ndarray, params: ParameterSet) -> np.ndarray:
    """Each column's largest difference over its norm; a compliance column of an actuator
    (almost) no load reaches (the arm's first and last) over the largest compliance column."""
    norm = np.linalg.norm(jac, axis=0)
    comp = params.is_compliance
    floor = np.where(comp, 1e-3 * norm[comp].max(), 0.0)
    return np.abs(fd - jac).max(axis=0) / np.maximum(norm, floor)


# the arm's masses are MuJoCo's placeholders: per kg of payload, the cobot's 2e-5 rad/(N m)
# (5e4 N m/rad) times 5 kg; the hexapod's geoms have masses: its own weight and 5 kg on legs
# of 1e-6 m/N (1e6 N/m)
@pytest.mark.parametrize(
    "name, payload_kg, size", [("arm6r_3targets", None, 1e-4), ("hexapod", 5.0, 1e-6)]
)
def test_jacobian_with_compliances_against_finite_differences(name, payload_kg, size, monkeypatch):
    mech, params, commands = _machine(name, payload_kg)
    model = CalibrationModel(mech, params)
    c = commands[:3]
    # at zero compliance (where identify starts) every column is the exact derivative
    x0 = np.where(params.is_compliance, 0.0, _draw(params, np.random.default_rng(2), 0.0))
    jac0 = model.jacobian(x0, model.predict(x0, c))
    rel0 = _relative(_fd(model, x0, c, size), jac0, params)
    assert np.linalg.norm(jac0[:, params.is_compliance], axis=0).max() > 1e-3
    assert np.max(rel0) < 1e-6, params.names[int(np.argmax(rel0))]
    # with compliances the columns hold the loads at the settled configuration: exact for
    # the model whose loads are held there
    x = _draw(params, np.random.default_rng(3), size)
    pred = model.predict(x, c)
    jac = model.jacobian(x, pred)
    full = _relative(_fd(model, x, c, size), jac, params)
    held = model.loads(x, pred.qpos)
    monkeypatch.setattr(joint_compliance, "gravity_loads", lambda *a, **k: held)
    monkeypatch.setattr(calib_model, "gravity_loads", lambda *a, **k: held)
    model._loads = None
    rel = _relative(_fd(model, x, c, size), jac, params)
    assert np.max(rel) < 1e-6, params.names[int(np.argmax(rel))]
    # what holding them leaves out (k dL/dq and k dL/d(geometry)) is of the order of the
    # deflection per load change: 5e-4 (arm) and 2e-3 (hexapod) of a column here at most
    assert 1e-6 < np.max(full) < 5e-3, np.max(full)


def test_column_jacobian_with_extra_compliances():
    """ColumnJacobian (the loop's and the diagnosis's one pass) with compliances among the
    chosen columns and among the extra parameters: the model's own columns."""
    mech, params, commands = _machine("arm6r_3targets")
    model = CalibrationModel(mech, params)
    x = _draw(params, np.random.default_rng(5), 1e-4)
    pred = model.predict(x, commands[:3])
    full = model.jacobian(x, pred)
    comp = np.flatnonzero(params.is_compliance)
    cols = np.array([comp[2], 0, comp[1], len(params) - 1, 4])
    geometric = [p for p in params.parameters if p.kind != "joint_compliance"]
    lean = CalibrationModel(mech, ParameterSet(geometric, mech.model))
    # the model without compliances, its joints the settled ones, plus them as extra columns
    extra = ParameterSet([params.parameters[k] for k in comp], mech.model)
    settled = model.joints_for_commands(x, commands[:3])
    xl = x[~params.is_compliance]
    got = ColumnJacobian.of(model, cols)(x, pred)
    np.testing.assert_allclose(got, full[:, cols], rtol=0, atol=1e-13)
    plain = lean.predict(xl, lean.commands_for_joints(xl, settled))
    extra_cols = ColumnJacobian.of(lean, np.arange(3), extra)(xl, plain)[:, 3:]
    np.testing.assert_allclose(extra_cols, full[:, comp], rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "name, payload_kg, effect",
    [
        ("arm6r_3targets", None, JointCompliance(5e4, payload_kg=5.0)),
        ("massive", 5.0, JointCompliance(5e4, payload_kg=5.0)),
        ("hexapod", 5.0, JointCompliance(1.0, 1e6, payload_kg=5.0)),
    ],
)
def test_noise_free_recovery_of_geometry_gains_and_compliances(name, payload_kg, effect):
    """Twin readings of a truth with geometric errors, the twin's ActuatorGain and its
    JointCompliance (the real masses and a 5 kg payload at the tool point; its own fixed
    point): the calibration, which sees only commands and readings, gives everything back."""
    mech, params, commands = _machine(name, payload_kg)
    model = CalibrationModel(mech, params)
    zero = np.zeros(len(params))
    start = analyse(model.jacobian(zero, model.predict(zero, commands)), params.names)
    free = np.array([n in start.identifiable for n in params.names])
    # joint 1 is vertical (no load reaches it) and the payload and the last link's mass sit
    # on joint 6's axis: no column at all
    unseen = {"A1", "A6"} if mech.is_serial else set()
    comp = params.is_compliance
    assert {params.parameters[k].element for k in np.flatnonzero(comp & ~free)} == unseen
    rng = np.random.default_rng(7)
    truth = np.where(free, _draw(params, rng, 0.0), 0.0)  # the redundant members at zero
    if mech.is_serial:
        # a level base (joint 1 vertical: no load on it); and the payload at the tool site,
        # which link6.d moves and a common dz of the reflectors does not, tells the two apart
        # only through k dL/dd (1e-3 of their columns), which identify's redundancy analysis
        # at zero compliance does not see: whichever of them it fixes is zero in the truth
        for n in ("link1.alpha", "link6.d", "target_1.dz"):
            truth[params.index(n)] = 0.0
    geometry = ParameterSet(
        [p for k, p in enumerate(params.parameters) if params.is_geometric[k]], mech.model
    )
    truth_mech = mech.with_model(geometry.inject(mech.model, truth[params.is_geometric]))
    gains = ActuatorGain(gains_ppm=tuple(truth[params.is_gain] * 1e6))
    k = effect.stiffness(mech)[
        [
            mech.actuator_names.index(p.element)
            for p in (params.parameters[i] for i in np.flatnonzero(comp))
        ]
    ]
    truth[comp] = np.where(free[comp], (1.0 if payload_kg is not None else 5.0) / k, 0.0)
    readings = measure(truth_mech, commands, EXACT, rng, effects=[gains, effect])
    obs = Observations(commands, readings.readings.mean(axis=2))
    res = identify(model, obs, unidentifiable="fix")
    assert res.converged and res.residual_rms < 1e-12
    assert np.array_equal(res.estimated & comp, free & comp)
    shown = params.to_display(res.values - truth)
    assert np.max(np.abs(shown[comp & free])) < 1e-8  # deg/(kN m) (kg), mm/kN (kg)
    assert np.max(np.abs(shown[params.is_gain])) < 1e-6  # ppm
    if np.array_equal(res.estimated, free):
        assert np.max(np.abs(res.values - truth)[params.is_geometric]) < 1e-11  # m, rad
    other = (commands[:-1] + commands[1:]) / 2  # strokes are boxes, convex
    got = model.predict(res.values, other).targets
    want = measure(truth_mech, other, EXACT, rng, effects=[gains, effect]).readings.mean(axis=2)
    assert np.max(np.abs(got - want)) < 1e-11


@pytest.mark.parametrize(
    "name, payload_kg, effect",
    [
        ("hexapod", 5.0, JointCompliance(1.0, 1e6, payload_kg=5.0)),
        ("arm6r_3targets", None, JointCompliance(5e4, payload_kg=5.0)),
    ],
)
def test_commands_for_poses_and_compensation_through_the_compliance(name, payload_kg, effect):
    """Inverse kinematics through compliances and gains returns commands; the truth machine
    with the same geometry, gains and the twin's compliance puts its targets where the
    model's inverse kinematics put them."""
    mech, params, commands = _machine(name, payload_kg)
    model = CalibrationModel(mech, params)
    x = _draw(params, np.random.default_rng(3), 0.0)
    x[params.is_compliance] = (1.0 if payload_kg is not None else 5.0) / effect.stiffness(mech)
    nominal = forward_batch(mech, commands[:4])
    poses = np.hstack([nominal.tool_position, rpy_from_matrix(nominal.tool_rotation)])
    if mech.workspace_min is not None:  # the hexapod: the model's own inverse kinematics
        got = model.commands_for_poses(x, poses)
        np.testing.assert_array_equal(compensated_commands(model, x, poses), got)
        joints = model.solved_configurations(x, poses)[:, mech.actuator_qpos]
    else:  # the arm has no workspace box: the compensation's pose by pose solve
        got, reachable = reachable_compensated_commands(model, x, poses)
        assert reachable.all()
        joints = solve_each(model.mechanism(x), poses).commands
    assert np.min(np.abs(got - joints).max(axis=0)) > 1e-6  # the sag, m or rad
    settled = model.joints_for_commands(x, got)
    np.testing.assert_allclose(settled, joints, rtol=0, atol=1e-13)
    sol = forward_batch(model.mechanism(x), settled, check_stroke=False)
    np.testing.assert_allclose(sol.tool_position, poses[:, :3], rtol=0, atol=1e-12)
    geometry = ParameterSet(
        [p for k, p in enumerate(params.parameters) if params.is_geometric[k]], mech.model
    )
    truth = mech.with_model(geometry.inject(mech.model, x[params.is_geometric]))
    effects = [ActuatorGain(gains_ppm=tuple(x[params.is_gain] * 1e6)), effect]
    measured = measure(truth, got, EXACT, np.random.default_rng(0), effects=effects)
    np.testing.assert_allclose(measured.readings.mean(axis=2), sol.targets, rtol=0, atol=1e-11)
    # rows that are not finite stay so (compensate writes NaN for unreachable poses)
    half = got.copy()
    half[1] = np.nan
    assert np.all(np.isnan(model.joints_for_commands(x, half)[1]))
    assert np.all(np.isnan(model.commands_for_joints(x, half)[1]))


def test_units_files_and_errors(tmp_path):
    arm = Mechanism.from_xml(MODELS / "arm6r_3targets.xml")
    hexapod = Mechanism.from_xml(MODELS / "hexapod_rrrprr.xml")
    base = load_parameter_set(MODELS / "hexapod_rrrprr.params.toml", hexapod.model)
    path = tmp_path / "c.params.toml"
    path.write_text(
        (MODELS / "hexapod_rrrprr.params.toml").read_text()
        + '\n[[parameter]]\nname = "leg2.c"\nkind = "joint_compliance"\nelement = "leg2"\n'
        + '\n[[parameter]]\nname = "leg3.c"\nkind = "joint_compliance"\nelement = "leg3"\n'
        + "payload_kg = 2.5\n"
    )
    params = load_parameter_set(path, hexapod.model)
    assert params.units()[-2:] == ["m/N kg", "m/N"]
    assert params.display_units()[-2:] == ["mm/kN kg", "mm/kN"]
    assert params.parameters[-1].payload_kg == 2.5 and np.isnan(params.payload_kg[-2])
    x = _draw(params, np.random.default_rng(1), 1e-6)
    shown = params.to_display(x)
    np.testing.assert_array_equal(shown[:54], base.to_display(x[:54]))  # the others unchanged
    np.testing.assert_allclose(shown[54:], x[54:] * 1e6, rtol=1e-15)  # mm/kN = um/N
    np.testing.assert_allclose(params.from_display(shown), x, rtol=1e-15, atol=0)
    turning = ParameterSet([Parameter("a2", "joint_compliance", "A2")], arm.model)
    assert turning.display_units() == ["deg/(kN m) kg"] and turning.units() == ["rad/(N m) kg"]
    assert turning.to_display(np.array([1e-4]))[0] == pytest.approx(5.729578, rel=1e-6)
    injected = params.inject(hexapod.model, np.where(params.is_compliance, x, 0.0))
    for field in ("body_pos", "body_quat", "site_pos", "qpos0"):
        np.testing.assert_array_equal(getattr(injected, field), getattr(hexapod.model, field))
    with pytest.raises(ParameterError, match=r"geometric parameters only.*'leg2.c'"):
        target_jacobian_batch(hexapod, params, x, hexapod.home_qpos[None])
    with pytest.raises(ParameterError, match=r"'p': payload_kg belongs to a joint_compliance"):
        Parameter("p", "actuator_gain", "leg1", payload_kg=1.0)
    with pytest.raises(ParameterError, match=r"payload_kg must be a finite mass >= 0"):
        Parameter("p", "joint_compliance", "leg1", payload_kg=-1.0)
    path.write_text('[[parameter]]\nname = "c"\nkind = "joint_compliance"\nelement = "leg_3"\n')
    with pytest.raises(ParameterError, match=r"no actuator named 'leg_3' \(did you mean"):
        load_parameter_set(path, hexapod.model)


def test_the_diagnosis_compliance_as_parameters():
    """What identify --with adds for a named gravity_compliance: per kg on a model without
    masses, under the scanned payload on one with masses; actuators the fit did not see left
    out."""
    arm = CalibrationModel(
        Mechanism.from_xml(MODELS / "arm6r_3targets.xml"),
        load_parameter_set(
            MODELS / "arm6r_3targets.params.toml",
            Mechanism.from_xml(MODELS / "arm6r_3targets.xml").model,
        ),
    )
    unit = "deg/(kN m) kg"
    fitted = {
        f"A{i}.compliance_x_payload": {"value": 5.7, "std": 0.01, "unit": unit} for i in range(2, 6)
    }
    fitted |= {
        f"A{i}.compliance_x_payload": {"value": 0.0, "std": None, "unit": unit} for i in (1, 6)
    }
    got = compliance_parameters(arm, fitted)
    assert [p.name for p in got] == [f"A{i}.compliance_x_payload" for i in range(2, 6)]
    assert all(p.kind == "joint_compliance" and p.payload_kg is None for p in got)
    massive = _massive_arm()
    model = CalibrationModel(
        massive, load_parameter_set(MODELS / "arm6r_3targets.params.toml", massive.model)
    )
    shaped = {
        "A2.compliance": {"value": 1.0, "std": 0.1, "unit": "deg/(kN m)"},
        "payload": {"value": 4.2, "std": 0.3, "unit": "kg"},
    }
    got = compliance_parameters(model, shaped)
    assert [p.name for p in got][:2] == ["A1.compliance", "A2.compliance"]
    assert {p.payload_kg for p in got} == {4.2}
