"""calib compensate: commands that put the identified machine at desired tool poses.

Round trips: the written commands put the identified machine (here also the truth) exactly at
the desired poses, on the serial arm and on the hexapod; position-only rows keep the nominal
orientation; tracker-frame poses go through the registration; an unreachable pose is named
with its actuator and amount while the others are written (exit 5); bad input writes nothing.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from to_machine_support import MODELS, ROOT, plausible_values, result_file

from calib.cli.commands import main
from calib.fit.registration import Registration
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.kinematics.batch import forward_batch
from twin.kinematics.single_pose import forward, pose_to_frame
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rpy, rotation_angle, rpy_from_matrix
from twin.workspace import random_poses

ARM, ARM_ERRORS = MODELS / "arm6r.xml", MODELS / "arm6r.params.toml"
HEXAPOD, HEXAPOD_ERRORS = MODELS / "hexapod_rrrprr.xml", MODELS / "hexapod_rrrprr.params.toml"


@pytest.fixture(scope="module")
def arm():
    nominal = Mechanism.from_xml(ARM)
    params = load_parameter_set(ARM_ERRORS, nominal.model)
    values = plausible_values(params, np.random.default_rng(21))
    return nominal, params, values, nominal.with_model(params.inject(nominal.model, values))


def _poses_csv(path, ids, positions_m, rpy_rad=None):
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["pose_id", "x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg"])
        for k, pid in enumerate(ids):
            ori = [""] * 3 if rpy_rad is None else np.degrees(rpy_rad[k]).tolist()
            w.writerow([pid, *(positions_m[k] * 1e3).tolist(), *ori])
    return path


def _read(path, mech):
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    scale = np.where(mech.actuator_is_slide, 1e-3, np.radians(1.0))
    cmds = np.array([[float(r[f"cmd:{a}"]) for a in mech.actuator_names] for r in rows]) * scale
    return rows, cmds


def _compensate(tmp_path, model, errors, result, poses, *extra):
    out = tmp_path / "commands.csv"
    args = ["compensate", "--model", str(model), "--errors", str(errors), "--result", str(result)]
    return main([*args, "--poses", str(poses), "--out", str(out), *extra]), out


def test_commands_put_the_identified_arm_at_the_desired_poses(arm, tmp_path, capsys):
    nominal, params, values, identified = arm
    rng = np.random.default_rng(22)
    lo, hi = nominal.actuator_range.T
    truth_cmds = rng.uniform(0.6 * lo, 0.6 * hi, (8, nominal.n_actuators))
    sol = forward_batch(identified, truth_cmds)
    rpy = rpy_from_matrix(sol.tool_rotation)
    poses = _poses_csv(tmp_path / "poses.csv", [f"p{k}" for k in range(8)], sol.tool_position, rpy)
    result = result_file(tmp_path / "r.json", "arm6r", params, values)
    code, out = _compensate(tmp_path, ARM, ARM_ERRORS, result, poses)
    assert code == 0, capsys.readouterr().err
    rows, cmds = _read(out, nominal)
    assert [r["pose_id"] for r in rows] == [f"p{k}" for k in range(8)]
    reached = forward_batch(identified, cmds)
    assert np.max(np.abs(reached.tool_position - sol.tool_position)) < 1e-9
    assert (
        np.max(rotation_angle(np.swapaxes(reached.tool_rotation, 1, 2) @ sol.tool_rotation)) < 1e-9
    )
    assert all(float(r["predicted_residual_mm"]) < 1e-6 for r in rows)
    # the nominal commands would miss by the size of the errors, which compensation removes
    assert all(0.05 < float(r["predicted_error_nominal_mm"]) < 5 for r in rows)
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["units"]["cmd:A1"] == "deg" and side["n_written"] == 8 and not side["unreachable"]


def test_position_only_rows_keep_the_nominal_orientation_and_tracker_frame_is_registered(
    arm, tmp_path, capsys
):
    nominal, params, values, identified = arm
    home = forward(nominal, nominal.home_qpos[nominal.actuator_qpos])
    rot = matrix_from_rpy(np.radians([3.0, -2.0, 95.0]))
    reg = Registration(rot, np.array([3.5, -1.2, 0.4]))  # base_from_tracker
    offsets = np.array([[0.0, 0.0, 0.0], [0.08, -0.05, 0.04], [-0.06, 0.1, -0.08]])
    wanted_base = home.tool_position + offsets
    poses = _poses_csv(tmp_path / "poses.csv", ["1", "2", "3"], reg.to_tracker(wanted_base))
    result = result_file(tmp_path / "r.json", "arm6r", params, values, registration=reg)
    code, out = _compensate(tmp_path, ARM, ARM_ERRORS, result, poses, "--frame", "tracker")
    assert code == 0, capsys.readouterr().err
    _, cmds = _read(out, nominal)
    reached = forward_batch(identified, cmds)
    assert (
        np.max(np.abs(reg.to_tracker(reached.tool_position) - reg.to_tracker(wanted_base))) < 1e-9
    )
    turn = rotation_angle(np.swapaxes(reached.tool_rotation, 1, 2) @ home.tool_rotation)
    assert np.max(turn) < 1e-9  # the nominal orientation, in the base frame
    # a base-frame result has no registration for tracker-frame poses
    base_result = result_file(tmp_path / "b.json", "arm6r", params, values)
    (tmp_path / "commands.csv").unlink()
    code, out = _compensate(tmp_path, ARM, ARM_ERRORS, base_result, poses, "--frame", "tracker")
    assert code == 2 and "no tracker registration" in capsys.readouterr().err
    assert not out.exists()


def test_unreachable_poses_are_named_and_the_others_written(arm, tmp_path, capsys):
    nominal, params, values, identified = arm
    home = forward(nominal, nominal.home_qpos[nominal.actuator_qpos])
    a3_past = nominal.home_qpos[nominal.actuator_qpos].copy()
    a3_past[2] = np.radians(75.0)  # A3's range is -155..70 deg
    past = forward(identified, a3_past, check_stroke=False)
    positions = np.array([home.tool_position, [3.0, 0.0, 0.5], past.tool_position])
    rpy = np.array(
        [rpy_from_matrix(home.tool_rotation)] * 2 + [rpy_from_matrix(past.tool_rotation)]
    )
    poses = _poses_csv(tmp_path / "poses.csv", ["home", "far", "past"], positions, rpy)
    result = result_file(tmp_path / "r.json", "arm6r", params, values)
    code, out = _compensate(tmp_path, ARM, ARM_ERRORS, result, poses)
    assert code == 5
    err = capsys.readouterr().err
    assert "pose_id far: out of reach" in err
    assert "pose_id past: actuator 'A3' needs 75 deg, 5 deg past its range [-155, 70] deg" in err
    rows, _ = _read(out, nominal)
    assert [r["pose_id"] for r in rows] == ["home"]
    side = json.loads(out.with_suffix(".json").read_text())
    assert [u["pose_id"] for u in side["unreachable"]] == ["far", "past"]


def test_hexapod_commands_reach_the_poses_and_a_stroke_is_named(tmp_path, capsys):
    nominal = Mechanism.from_xml(HEXAPOD)
    params = load_parameter_set(HEXAPOD_ERRORS, nominal.model)
    values = load_values(ROOT / "scenarios/truth/hexapod_table2.toml", params)
    truth = nominal.with_model(params.inject(nominal.model, values))
    poses, _ = random_poses(nominal, 6, np.random.default_rng(23))
    stretched = poses[0].copy()
    stretched[2] = 0.24  # top of the box, tilted: a limb past its stroke
    stretched[3:] = np.radians([15.0, 15.0, 20.0])
    all_poses = np.vstack([poses, stretched])
    ids = [str(k) for k in range(7)]
    csv_path = _poses_csv(tmp_path / "p.csv", ids, all_poses[:, :3], all_poses[:, 3:])
    result = result_file(tmp_path / "r.json", nominal.name, params, values)
    code, out = _compensate(tmp_path, HEXAPOD, HEXAPOD_ERRORS, result, csv_path)
    assert code == 5
    assert "pose_id 6: actuator 'leg" in capsys.readouterr().err
    rows, cmds = _read(out, nominal)
    assert [r["pose_id"] for r in rows] == ids[:6]
    reached = forward_batch(truth, cmds)
    rot, pos = pose_to_frame(poses)
    assert np.max(np.abs(reached.tool_position - pos)) < 1e-9
    assert np.max(rotation_angle(np.swapaxes(reached.tool_rotation, 1, 2) @ rot)) < 1e-9


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("pose_id,x_mm,y_mm\n1,1,2\n", "missing column(s) ['z_mm']"),
        ("pose_id,x_mm,y_mm,z_mm,rx_deg\n1,1,2,3,4\n", "give all three or none"),
        ("pose_id,x_mm,y_mm,z_mm,rx_deg,ry_deg,rz_deg\n1,1,2,3,4,,\n", "gives ['rx_deg']"),
        ("pose_id,x_mm,y_mm,z_mm\n1,1,2,three\n", "'three' is not a number"),
        ("pose_id,x_mm,y_mm,z_mm\n1,1,2,3\n1,1,2,3\n", "pose_id '1' appears twice"),
        ("pose_id,x_mm,y_mm,zz_mm\n1,1,2,3\n", "did you mean 'z_mm'"),
        ("", "empty file"),
    ],
)
def test_bad_desired_pose_files_are_named_and_nothing_is_written(
    arm, tmp_path, capsys, text, message
):
    _, params, values, _ = arm
    poses = tmp_path / "poses.csv"
    poses.write_text(text)
    result = result_file(tmp_path / "r.json", "arm6r", params, values)
    code, out = _compensate(tmp_path, ARM, ARM_ERRORS, result, poses)
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists() and not out.with_suffix(".json").exists()


def test_another_machines_result_is_refused(tmp_path, capsys):
    hexapod = Mechanism.from_xml(HEXAPOD)
    params = load_parameter_set(HEXAPOD_ERRORS, hexapod.model)
    result = result_file(tmp_path / "r.json", hexapod.name, params, np.zeros(len(params)))
    poses = tmp_path / "p.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm\n1,500,0,800\n")
    code, out = _compensate(tmp_path, ARM, ARM_ERRORS, result, poses)
    assert code == 2 and "another machine" in capsys.readouterr().err
    assert not out.exists()


def test_identified_actuator_gains_turn_joint_values_into_commands(tmp_path, capsys):
    """A result of identify --with (gains added to the error model): the commands differ from
    the joint values by the gains, and the joints they give put the tool at the poses."""
    from calib.compensate.identified_machine import load_identified_machine
    from calib.fit.observations import model_from_files
    from twin.parameters import Parameter, ParameterSet

    nominal = Mechanism.from_xml(HEXAPOD)
    base = load_parameter_set(HEXAPOD_ERRORS, nominal.model)
    gains = [Parameter(f"{a}.gain", "actuator_gain", a) for a in nominal.actuator_names]
    params = ParameterSet([*base.parameters, *gains], nominal.model)
    geometry = load_values(ROOT / "scenarios/truth/hexapod_table2.toml", base)
    ppm = np.array([300.0, -200.0, 150.0, 0.0, 500.0, -400.0]) * 1e-6
    values = np.concatenate([geometry, ppm])
    result = result_file(tmp_path / "r.json", nominal.name, params, values, added=gains)
    poses, _ = random_poses(nominal, 5, np.random.default_rng(24))
    csv_path = _poses_csv(tmp_path / "p.csv", list("abcde"), poses[:, :3], poses[:, 3:])
    code, out = _compensate(tmp_path, HEXAPOD, HEXAPOD_ERRORS, result, csv_path)
    assert code == 0, capsys.readouterr().err
    _, cmds = _read(out, nominal)
    machine = load_identified_machine(model_from_files(str(HEXAPOD), str(HEXAPOD_ERRORS)), result)
    assert machine.model.params.names == params.names
    joints = machine.joints_for_commands(cmds)
    zero = machine.model.joint_zeros(machine.values)
    assert np.allclose(joints - zero, (cmds - zero) * (1 + ppm), rtol=0, atol=1e-15)
    assert np.array_equal(joints[:, 3], cmds[:, 3])  # leg4 has none
    reached = forward_batch(machine.mechanism, joints, check_stroke=False)
    rot, pos = pose_to_frame(poses)
    assert np.max(np.abs(reached.tool_position - pos)) < 1e-9
    assert np.max(rotation_angle(np.swapaxes(reached.tool_rotation, 1, 2) @ rot)) < 1e-9
    # export writes the geometry and the gains, as the actuators' gears (leg4 has none)
    exported = tmp_path / "h.xml"
    args = ["export", "--model", str(HEXAPOD), "--errors", str(HEXAPOD_ERRORS)]
    assert main([*args, "--result", str(result), "--out", str(exported)]) == 0
    said = capsys.readouterr().out
    assert "5 actuator gains as gears" in said and "holds every identified parameter" in said
    written = Mechanism.from_xml(exported)
    gear = np.array([written.actuator_gear[i] for i in range(6)])
    np.testing.assert_allclose(gear, 1.0 / (1.0 + ppm), rtol=1e-12)
