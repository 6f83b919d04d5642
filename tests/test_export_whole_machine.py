"""calib export carries the whole machine: actuator gains in the MJCF, the rest in a sidecar.

A hexapod whose six legs have gains (the twin's ActuatorGain effect; calib sees only the
Dataset) is identified with gain parameters, exported, and scored as it is (``verify --model
exported.xml``): it must predict the held-out readings as the result itself does (within 2 %;
the two differ only in the registration, fitted with the parameters by identify and to the
model alone by verify --model), and its forward kinematics must equal the identified model's
at the same commands to 1e-9 m, in MuJoCo's own terms too (a position servo of gear G settles
where G qpos = ctrl). A result with joint compliances exports them to the sidecar, and
verify --model says so in its first line.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
from to_machine_support import MODELS, plausible_values, result_file

from calib.cli.commands import main
from calib.compensate.identified_machine import load_identified_machine
from calib.compensate.model_export import gained_joints, geometry, probe_commands
from calib.data import write_dataset
from calib.fit import model_from_files
from scenarios.twin_datasets import measured_dataset, tracker_frame_dataset
from twin.effects import ActuatorGain
from twin.exceptions import ModelError
from twin.formats.mjcf_values import mjcf_with_values
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

LEG_GAINS_PPM = (-6000.0, 2500.0, 4000.0, -1500.0, 800.0, -3000.0)  # screw leads, a few 0.1 %


def _gain_toml(tmp_path, mech: Mechanism):
    text = (MODELS / "hexapod_rrrprr.params.toml").read_text()
    for a in mech.actuator_names:
        text += f'\n[[parameter]]\nname = "{a}.gain"\nkind = "actuator_gain"\nelement = "{a}"\n'
    path = tmp_path / "hexapod_gains.params.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    """identify (with gains), verify of the result, export, verify of the exported model."""
    tmp = tmp_path_factory.mktemp("whole")
    model = MODELS / "hexapod_rrrprr.xml"
    nominal = Mechanism.from_xml(model)
    errors = _gain_toml(tmp, nominal)
    rng = np.random.default_rng(11)
    geometric = load_parameter_set(MODELS / "hexapod_rrrprr.params.toml", nominal.model)
    shown = np.where(geometric.is_angle, 0.0, rng.uniform(-0.4, 0.4, len(geometric)))
    truth = nominal.with_model(geometric.inject(nominal.model, geometric.from_display(shown)))
    tracker = Tracker(
        position_m=(1.4, -0.6, 0.9),
        noise=TrackerNoise.from_spec("gaussian 5 um"),
        rotation_rpy_rad=tuple(np.radians([1.0, -2.0, 30.0])),
    )
    _, commands = random_poses(nominal, 90, rng)
    effects = [ActuatorGain(gains_ppm=LEG_GAINS_PPM)]
    ds = tracker_frame_dataset(truth, tracker, commands, 60, 0.005, rng, effects)
    data = write_dataset(ds, tmp / "readings.csv")
    result, exported = tmp / "r.json", tmp / "hexapod_cal.xml"
    common = ["--model", str(model), "--errors", str(errors)]
    verify = ["verify", "--data", str(data), "--set", "test"]
    codes = {
        "identify": main(["identify", *common, "--data", str(data), "--out", str(result)]),
        "verify": main(
            [*verify, *common, "--result", str(result), "--out", str(tmp / "v_result.json")]
        ),
        "export": main(["export", *common, "--result", str(result), "--out", str(exported)]),
        "as_is": main([*verify, "--model", str(exported), "--out", str(tmp / "v_as_is.json")]),
    }
    return SimpleNamespace(
        tmp=tmp,
        model=model,
        errors=errors,
        result=result,
        exported=exported,
        data=data,
        codes=codes,
    )


def test_exported_gains_predict_as_the_result(loop, capsys):
    tmp, model, errors, result, data = loop.tmp, loop.model, loop.errors, loop.result, loop.data
    assert loop.codes == {"identify": 0, "verify": 0, "export": 0, "as_is": 0}
    found = json.loads(result.read_text())["parameters"]
    assert all(abs(found[f"leg{i}.gain"]["value"]) > 500 for i in range(1, 7))  # ppm
    own = json.loads((tmp / "v_result.json").read_text())
    as_is = json.loads((tmp / "v_as_is.json").read_text())
    own_rms = own["after"]["rms_mm"]
    as_is_rms = as_is["as_is"]["rms_mm"]
    print("result's verify", own_rms, "exported as is", as_is_rms)
    assert abs(as_is_rms - own_rms) <= 0.02 * own_rms
    assert "model_lacks" not in as_is  # gains and geometry are all in the file
    # the geometry alone (what export wrote before), scored as it is: the gains' effect is lost
    machine = load_identified_machine(model_from_files(model, errors), result)
    params, values = geometry(machine)
    no_gears = tmp / "hexapod_no_gears.xml"
    no_gears.write_text(mjcf_with_values(model, machine.nominal.model, params, values).text)
    v = tmp / "v_no_gears.json"
    args = ["verify", "--model", str(no_gears), "--data", str(data), "--set", "test"]
    assert main([*args, "--out", str(v)]) == 0
    without = json.loads(v.read_text())["as_is"]["rms_mm"]
    print("without gears", without)
    assert without > 5 * own_rms
    side = json.loads((tmp / "hexapod_cal.xml.calibration.json").read_text())
    assert side["not_held"] == [] and len(side["held_in_model"]["actuator_gains"]) == 6


def test_exported_gears_are_mujocos_own_servo_equilibrium(loop):
    """In MuJoCo's own terms: at the configuration the exported model closes in for commands c,
    each position servo's length (gear x qpos, mj_fwdPosition) is c, its set point, and the
    targets are where the identified model (gains applied to c) puts them; the gears are
    1 / (1 + gain), the strokes and the home commands those of the nominal model."""
    model, errors, result, exported = loop.model, loop.errors, loop.result, loop.exported
    machine = load_identified_machine(model_from_files(model, errors), result)
    params = machine.model.params
    m = mujoco.MjModel.from_xml_path(str(exported))
    mech = Mechanism.from_xml(exported)
    gains = machine.values[params.is_gain]
    np.testing.assert_allclose(m.actuator_gear[:, 0], 1.0 / (1.0 + gains), rtol=1e-15, atol=0)
    np.testing.assert_allclose(mech.actuator_range, machine.nominal.actuator_range, atol=1e-15)
    np.testing.assert_allclose(mech.home_commands, machine.nominal.home_commands, atol=1e-15)
    _, commands = random_poses(machine.nominal, 6, np.random.default_rng(2))
    joints = gained_joints(machine, commands)
    identified = forward_batch(machine.mechanism, joints, check_stroke=False)
    closed = forward_batch(mech, commands)
    d = mujoco.MjData(m)
    for c, q, targets in zip(commands, closed.qpos, identified.targets, strict=True):
        d.qpos[:] = q
        mujoco.mj_fwdPosition(m, d)
        np.testing.assert_allclose(d.actuator_length, c, rtol=0, atol=1e-15)
        assert np.max(np.abs(d.site_xpos[mech.target_sites] - targets)) < 1e-9


def test_calibration_of_a_geared_model_is_refused(loop):
    with pytest.raises(ModelError, match="joint is not their command"):
        model_from_files(loop.exported, loop.errors)


def test_what_the_mjcf_cannot_hold_is_in_the_sidecar_and_verify_says_so_first(tmp_path, capsys):
    xml = MODELS / "arm6r.xml"
    nominal = Mechanism.from_xml(xml)
    text = (MODELS / "arm6r.params.toml").read_text()
    for a in ("A2", "A3"):
        text += f'\n[[parameter]]\nname = "{a}.compliance"\nkind = "joint_compliance"\n'
        text += f'element = "{a}"\n'
    toml = tmp_path / "arm_compliant.params.toml"
    toml.write_text(text)
    params = load_parameter_set(toml, nominal.model)
    values = plausible_values(params, np.random.default_rng(3))
    # per kg of payload: 2e-5 rad/(N m) of a stiff cobot joint, 5 kg (deg/(kN m) kg in files)
    values[params.is_compliance] = [2e-5 * 5, 1e-5 * 5]
    result = result_file(tmp_path / "r.json", nominal.name, params, values)
    out = tmp_path / "arm_cal.xml"
    args = ["export", "--model", str(xml), "--errors", str(toml), "--result", str(result)]
    assert main([*args, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    side = tmp_path / "arm_cal.xml.calibration.json"
    assert f"wrote {side}: 2 identified parameter(s) the MJCF cannot hold" in printed
    content = json.loads(side.read_text())
    shown = params.to_display(values)
    assert [m["name"] for m in content["not_held"]] == ["A2.compliance", "A3.compliance"]
    for m, k in zip(content["not_held"], np.flatnonzero(params.is_compliance), strict=True):
        assert m["kind"] == "joint_compliance" and m["element"] == params.parameters[k].element
        assert m["value"] == shown[k] and m["unit"] == "deg/(kN m) kg"
    rng = np.random.default_rng(4)
    commands = probe_commands(nominal, 5)
    poses = np.zeros((len(commands), 6))  # not used by the readings
    ds = measured_dataset(nominal, commands, poses, "test", Tracker(noise=TrackerNoise.none()), rng)
    data = write_dataset(ds, tmp_path / "readings.csv")
    v = tmp_path / "v.json"
    assert main(["verify", "--model", str(out), "--data", str(data), "--out", str(v)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("WARNING: this model lacks 2 identified parameter(s)")
    assert "A2.compliance (joint_compliance, " in first and "A3.compliance" in first
    assert json.loads(v.read_text())["model_lacks"] == first
    # an unreadable sidecar is said first as well; the nominal model (no sidecar) says nothing
    side.write_text("{not json")
    assert main(["verify", "--model", str(out), "--data", str(data)]) == 0
    assert capsys.readouterr().out.startswith(f"WARNING: {side} (what this model lacks)")
    assert main(["verify", "--model", str(xml), "--data", str(data)]) == 0
    assert not capsys.readouterr().out.startswith("WARNING")
