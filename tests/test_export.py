"""calib export: the nominal MJCF with the identified errors in its geometry, and the DH table.

The exported file's forward kinematics must equal the identified model's (the nominal model
with the values injected in memory) to 1e-9 m on the arm, the hexapod and the polisher; the
calibrated DH table must give the same model again; a model written in degrees, with frames
and Euler angles, too; verify --model scores an exported model as it is; bad input writes
nothing.
"""

from __future__ import annotations

import json
import shutil

import mujoco
import numpy as np
import pytest
from to_machine_support import MODELS, ROOT, plausible_values, result_file

from calib.cli.commands import main
from calib.compensate.model_export import kinematics_difference, probe_commands
from calib.data import write_dataset
from scenarios.twin_datasets import measured_dataset
from twin.formats.dh_extract import dh_table_of
from twin.formats.dh_mjcf import build_xml, exact
from twin.formats.dh_table import parse_dh_table, read_dh_table
from twin.formats.error_model import error_parameters
from twin.formats.mjcf_values import mjcf_with_values
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.mechanism import Mechanism
from twin.parameters import Parameter, ParameterSet
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

MACHINES = {
    "arm": ("arm6r.xml", "arm6r.params.toml"),
    "hexapod": ("hexapod_rrrprr.xml", "hexapod_rrrprr.params.toml"),
    "polisher": ("polisher.xml", "polisher.params.toml"),
}


@pytest.mark.parametrize("machine", list(MACHINES))
def test_exported_model_has_the_identified_kinematics(machine, tmp_path):
    xml, toml = (MODELS / f for f in MACHINES[machine])
    nominal = Mechanism.from_xml(xml)
    params = load_parameter_set(toml, nominal.model)
    values = plausible_values(params, np.random.default_rng(7))
    identified = nominal.with_model(params.inject(nominal.model, values))
    written = mjcf_with_values(
        xml, nominal.model, params, values, out_dir=tmp_path, bound_masses=True
    )
    out = tmp_path / xml.name
    out.write_text(written.text)
    mujoco.MjModel.from_xml_path(str(out))  # MuJoCo alone loads it (bounded masses added)
    exported = Mechanism.from_xml(out)
    check = kinematics_difference(identified, exported, probe_commands(nominal))
    assert check.n_commands >= 20
    assert check.max_position_m < 1e-9 and check.max_rotation_rad < 1e-9
    # the rest of the file is the user's: every line not naming a changed element is kept
    changed = {*written.bodies, *written.sites, *written.joints}
    kept = [
        line
        for line in xml.read_text().splitlines()
        if not any(f'name="{n}"' in line for n in changed) and "<compiler" not in line
    ]
    assert set(kept) <= set(written.text.splitlines())
    assert len(changed) > 0


TOY = """<mujoco model="toy">
  <compiler angle="degree"/>
  <worldbody>
    <body name="base">
      <frame pos="0 0 0.1" euler="0 0 30">
        <body name="l1" pos="0.1 0 0.2" euler="10 20 30">
          <joint name="j1" axis="0 0 1" ref="5" range="-170 170"/>
          <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/>
          <body name="l2" pos="0.3 0 0" axisangle="1 0 0 90">
            <joint name="j2" axis="0 1 0" range="-170 170"/>
            <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02"/>
            <frame pos="0.2 0 0" quat="0.9 0.1 0 0">
              <site name="tool" pos="0.05 0 0"/>
              <site name="target_1" pos="0.05 0.02 0.01"/>
            </frame>
          </body>
        </body>
      </frame>
    </body>
  </worldbody>
  <actuator><motor name="j1" joint="j1"/><motor name="j2" joint="j2"/></actuator>
</mujoco>
"""


def test_export_writes_into_frames_euler_angles_and_degrees(tmp_path):
    path = tmp_path / "toy.xml"
    path.write_text(TOY)
    nominal = Mechanism.from_xml(path)
    axes = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    params = ParameterSet(
        [Parameter(f"l1.d{k}", "body_pos", "l1", a) for k, a in enumerate(axes)]
        + [Parameter(f"l1.r{k}", "body_rot", "l1", a) for k, a in enumerate(axes)]
        + [Parameter("l2.rx", "body_rot", "l2", axes[0])]
        + [Parameter(f"t.d{k}", "site_pos", "target_1", a) for k, a in enumerate(axes)]
        + [Parameter("j1.zero", "joint_zero", "j1"), Parameter("j2.zero", "joint_zero", "j2")],
        nominal.model,
    )
    values = np.where(params.is_angle, np.radians(0.7), 2e-3) * np.linspace(-1, 1, len(params))
    text = mjcf_with_values(path, nominal.model, params, values).text
    assert 'euler="10 20 30"' not in text and "axisangle" not in text  # replaced by quat
    exported = Mechanism.from_xml_string(text)
    identified = nominal.with_model(params.inject(nominal.model, values))
    check = kinematics_difference(identified, exported, probe_commands(nominal))
    assert check.max_position_m < 1e-12 and check.max_rotation_rad < 1e-12


def _export(tmp_path, xml, toml, values, params, *extra):
    result = result_file(tmp_path / "result.json", Mechanism.from_xml(xml).name, params, values)
    out = tmp_path / "out" / "calibrated.xml"
    args = ["export", "--model", str(xml), "--errors", str(toml), "--result", str(result)]
    return main([*args, "--out", str(out), *extra]), out


def test_export_cli_writes_the_model_and_the_calibrated_dh_table(tmp_path, capsys):
    xml, toml = MODELS / "arm6r.xml", MODELS / "arm6r.params.toml"
    nominal = Mechanism.from_xml(xml)
    params = load_parameter_set(toml, nominal.model)
    values = plausible_values(params, np.random.default_rng(3))
    dh_out = tmp_path / "out" / "arm6r_calibrated.mdh.csv"
    code, out = _export(tmp_path, xml, toml, values, params, "--dh-out", str(dh_out))
    assert code == 0, capsys.readouterr().err
    said = capsys.readouterr().out
    assert "forward kinematics of the written model" in said and "calibrated DH table" in said
    identified = nominal.with_model(params.inject(nominal.model, values))
    rng = np.random.default_rng(4)
    lo, hi = nominal.actuator_range.T
    commands = rng.uniform(lo, hi, (100, nominal.n_actuators))
    assert (
        kinematics_difference(identified, Mechanism.from_xml(out), commands).max_position_m < 1e-9
    )
    # the calibrated DH table builds the same arm again (python -m twin.formats.dh_table)
    again = Mechanism.from_xml_string(build_xml(read_dh_table(dh_out), "arm6r", number=exact))
    assert kinematics_difference(identified, again, commands).max_position_m < 1e-9
    # with no errors the table read back from the model is the committed one
    table = dh_table_of(nominal.model)
    committed = read_dh_table(MODELS / "arm6r.mdh.csv").with_targets(["target_1"])
    for a, b in zip(table.joints, committed.joints, strict=True):
        assert a.name == b.name and a.type == b.type
        assert np.allclose([a.alpha, a.a, a.d, a.theta], [b.alpha, b.a, b.d, b.theta], atol=1e-12)
    assert parse_dh_table(dh_out.read_text()).convention == "modified"


def test_dh_out_refuses_a_geometry_no_dh_row_holds_and_writes_nothing(tmp_path, capsys):
    xml = MODELS / "arm6r.xml"
    nominal = Mechanism.from_xml(xml)
    params = error_parameters(nominal)  # the complete model: offsets a DH row cannot hold
    toml = tmp_path / "complete.params.toml"
    from twin.formats.error_model import error_model_toml

    toml.write_text(error_model_toml(nominal, str(xml)))
    values = np.zeros(len(params))
    values[params.index("link3.dy")] = 2e-4
    dh_out = tmp_path / "out" / "t.csv"
    code, out = _export(tmp_path, xml, toml, values, params, "--dh-out", str(dh_out))
    assert code == 2
    err = capsys.readouterr().err
    assert "body 'link3' is offset along y" in err and "DH row cannot hold it" in err
    assert not out.exists() and not dh_out.exists()


def test_export_refuses_bad_input_and_writes_nothing(tmp_path, capsys):
    hexa, hexa_toml = MODELS / "hexapod_rrrprr.xml", MODELS / "hexapod_rrrprr.params.toml"
    nominal = Mechanism.from_xml(hexa)
    params = load_parameter_set(hexa_toml, nominal.model)
    # --dh-out for a model not generated from a DH table
    code, out = _export(
        tmp_path,
        hexa,
        hexa_toml,
        np.zeros(len(params)),
        params,
        "--dh-out",
        str(tmp_path / "t.csv"),
    )
    assert code == 2 and "not generated from a DH table" in capsys.readouterr().err
    assert not out.exists()
    # another machine's result
    result = tmp_path / "result.json"
    arm = MODELS / "arm6r.xml"
    args = ["export", "--model", str(arm), "--errors", str(MODELS / "arm6r.params.toml")]
    code = main([*args, "--result", str(result), "--out", str(tmp_path / "x.xml")])
    assert code == 2 and "another machine" in capsys.readouterr().err
    assert not (tmp_path / "x.xml").exists()
    # the nominal model as --out
    copy = tmp_path / "arm6r.xml"
    shutil.copy(arm, copy)
    arm_params = load_parameter_set(MODELS / "arm6r.params.toml", Mechanism.from_xml(arm).model)
    res = result_file(tmp_path / "arm.json", "arm6r", arm_params, np.zeros(len(arm_params)))
    args = ["export", "--model", str(copy), "--errors", str(MODELS / "arm6r.params.toml")]
    code = main([*args, "--result", str(res), "--out", str(copy)])
    assert code == 2 and "the nominal model itself" in capsys.readouterr().err
    assert copy.read_text() == arm.read_text()


def test_export_keeps_included_files_reachable_from_another_folder(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    (src / "actuators.xml").write_text(
        '<mujoco><actuator><motor name="j1" joint="j1"/><motor name="j2" joint="j2"/>'
        "</actuator></mujoco>"
    )
    (src / "toy.xml").write_text(
        TOY.replace("  <actuator>", '  <include file="actuators.xml"/>\n  <actuator>', 1).replace(
            '<actuator><motor name="j1" joint="j1"/><motor name="j2" joint="j2"/></actuator>', ""
        )
    )
    nominal = Mechanism.from_xml(src / "toy.xml")
    params = ParameterSet([Parameter("j1.zero", "joint_zero", "j1")], nominal.model)
    written = mjcf_with_values(
        src / "toy.xml", nominal.model, params, np.array([0.01]), out_dir=tmp_path / "elsewhere"
    )
    (tmp_path / "elsewhere").mkdir()
    out = tmp_path / "elsewhere" / "toy.xml"
    out.write_text(written.text)
    assert 'file="../src/actuators.xml"' in written.text
    exported = Mechanism.from_xml(out)
    assert exported.actuator_names == ("j1", "j2")


def test_verify_scores_an_exported_model_as_it_is(tmp_path, capsys):
    xml, toml = MODELS / "hexapod_rrrprr.xml", MODELS / "hexapod_rrrprr.params.toml"
    nominal = Mechanism.from_xml(xml)
    params = load_parameter_set(toml, nominal.model)
    truth_values = load_values(ROOT / "scenarios/truth/hexapod_table2.toml", params)
    truth = nominal.with_model(params.inject(nominal.model, truth_values))
    rng = np.random.default_rng(5)
    poses, commands = random_poses(nominal, 10, rng)
    ds = measured_dataset(truth, commands, poses, "test", Tracker(noise=TrackerNoise.none()), rng)
    data = write_dataset(ds, tmp_path / "readings.csv")
    code, out = _export(tmp_path, xml, toml, truth_values, params)
    assert code == 0
    capsys.readouterr()
    v = tmp_path / "v.json"
    assert main(["verify", "--model", str(out), "--data", str(data), "--out", str(v)]) == 0
    scored = json.loads(v.read_text())
    assert scored["as_is"]["max_mm"] < 1e-9 and scored["n_readings"] == 30
    assert main(["verify", "--model", str(xml), "--data", str(data)]) == 0
    assert "model as it is: 3D position error per reading RMS" in capsys.readouterr().out
    # --result without --errors is refused
    code = main(["verify", "--model", str(xml), "--data", str(data), "--result", str(v)])
    assert code == 2 and "needs --errors" in capsys.readouterr().err
