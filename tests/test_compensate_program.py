"""calib compensate --commands: a robot's program corrected on the identified machine.

A 6R arm is calibrated as a user does it (a truth drawn in the twin, readings through the
twin, ``identify``), then a program of 50 joint targets is compensated: the identified tool
frame reaches what the nominal model meant at each target, every joint stays within a degree
of the program, and the exported MJCF, loaded by MuJoCo alone, agrees. A parallel machine's
program with actuator gains in the result, a UR10-like arm whose position-only poses jump
branches without a seed and keep them with one, and a refused result (compensate and export)
complete it.
"""

from __future__ import annotations

import csv
import json

import mujoco
import numpy as np
import pytest
from to_machine_support import MODELS, ROOT, plausible_values, result_file

from calib.cli.commands import main
from calib.data import write_dataset
from scenarios.twin_datasets import measured_dataset
from twin.formats.dh_table import main as dh_table_main
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism
from twin.rotations import rotation_angle, rotvec_from_matrix
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

ARM, ARM_ERRORS = MODELS / "arm6r.xml", MODELS / "arm6r.params.toml"
HEXAPOD, HEXAPOD_ERRORS = MODELS / "hexapod_rrrprr.xml", MODELS / "hexapod_rrrprr.params.toml"
# the bounds: the identified tool at the intent to 1e-3 mm and 1e-3 deg, every joint
# within 1 deg of the program
REACH_M, REACH_RAD, JOINT_RAD = 1e-6, np.radians(1e-3), np.radians(1.0)


def _file_scale(mech: Mechanism) -> np.ndarray:
    return np.where(mech.actuator_is_slide, 1e3, np.degrees(1.0))


def _program_csv(path, mech, commands, ids=None, extra=None):
    ids = ids or [f"t{k}" for k in range(len(commands))]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["pose_id", *(f"cmd:{a}" for a in mech.actuator_names), *(extra or [])])
        for pid, c in zip(ids, commands * _file_scale(mech), strict=True):
            w.writerow([pid, *c.tolist(), *(["x"] * len(extra or []))])
    return path


def _read(path, mech):
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    cmds = np.array([[float(r[f"cmd:{a}"]) for a in mech.actuator_names] for r in rows])
    return rows, cmds / _file_scale(mech)


def _run(model, errors, result, *args):
    return main(["compensate", "--model", str(model), "--errors", str(errors), "--result",
                 str(result), *map(str, args)])  # fmt: skip


def _within(lo, hi, rng, n, fraction):
    mid, half = (lo + hi) / 2, fraction * (hi - lo) / 2
    return rng.uniform(mid - half, mid + half, (n, len(lo)))


@pytest.fixture(scope="module")
def calibrated_arm(tmp_path_factory):
    """arm6r with a drawn truth, 40 poses read by a 10 um tracker, identify -> result."""
    tmp = tmp_path_factory.mktemp("arm")
    nominal = Mechanism.from_xml(ARM)
    params = load_parameter_set(ARM_ERRORS, nominal.model)
    rng = np.random.default_rng(31)
    truth = nominal.with_model(params.inject(nominal.model, plausible_values(params, rng)))
    commands = _within(*nominal.actuator_range.T, rng, 40, 0.8)
    tracker = Tracker(noise=TrackerNoise.from_spec("gaussian 0.01 mm"))
    data = write_dataset(
        measured_dataset(truth, commands, None, "calibration", tracker, rng),
        tmp / "readings.csv",
    )  # fmt: skip
    result = tmp / "result.json"
    common = ["--model", str(ARM), "--errors", str(ARM_ERRORS)]
    assert main(["identify", *common, "--data", str(data), "--out", str(result)]) == 0
    return nominal, data, result, tmp


def test_a_calibrated_arms_program_reaches_the_nominal_intent_checked_in_mujoco(
    calibrated_arm, tmp_path, capsys
):
    from calib.compensate import load_identified_machine
    from calib.fit import model_from_files

    nominal, _, result, _ = calibrated_arm
    # a program as a planner writes it: away from singularities, where a tool frame's small
    # error needs large joint motions (the wrist at A5 = 0 turns A4 and A6 by tens of
    # degrees): the tool Jacobian's smallest singular value at least 0.1 (m, rad)
    drawn = _within(*nominal.actuator_range.T, np.random.default_rng(32), 200, 0.7)
    sigma = _mujoco_smallest_singular_value(ARM, nominal.actuator_names, drawn)
    program = drawn[sigma >= 0.1][:50]
    assert len(program) == 50
    prog_csv = _program_csv(tmp_path / "program.csv", nominal, program)
    out = tmp_path / "corrected.csv"
    assert _run(ARM, ARM_ERRORS, result, "--commands", prog_csv, "--out", out) == 0
    said = capsys.readouterr().out
    assert "compensated 50 of 50 program targets" in said
    rows, corrected = _read(out, nominal)
    assert [r["pose_id"] for r in rows] == [f"t{k}" for k in range(50)]
    assert list(rows[0])[: 1 + nominal.n_actuators] == [
        "pose_id", *(f"cmd:{a}" for a in nominal.actuator_names)
    ]  # fmt: skip
    # on the identified model (the result as calib reads it): the tool frame at the corrected
    # commands is the nominal model's at the program's
    machine = load_identified_machine(model_from_files(str(ARM), str(ARM_ERRORS)), result)
    intent = forward_batch(nominal, program)
    got = forward_batch(machine.mechanism, machine.joints_for_commands(corrected))
    assert np.max(np.linalg.norm(got.tool_position - intent.tool_position, axis=1)) < REACH_M
    turn = rotation_angle(np.swapaxes(got.tool_rotation, 1, 2) @ intent.tool_rotation)
    assert np.max(turn) < REACH_RAD
    change = np.abs(corrected - program)
    assert np.max(change) < JOINT_RAD  # the same branch: a correction, not another solution
    # and no more than the geometry asks: to first order the change is J^-1 e, so its norm is
    # at most |e| / sigma_min, e the tool frame's error at the program's commands
    raw = forward_batch(machine.mechanism, machine.joints_for_commands(program))
    e = np.hstack([
        raw.tool_position - intent.tool_position,
        rotvec_from_matrix(intent.tool_rotation @ np.swapaxes(raw.tool_rotation, 1, 2)),
    ])  # fmt: skip
    bound = np.linalg.norm(e, axis=1) / sigma[sigma >= 0.1][:50]
    assert np.all(np.linalg.norm(corrected - program, axis=1) <= 1.1 * bound)
    assert np.max(change) > np.radians(1e-3)  # errors of 0.05 deg do move the joints
    # independently, in MuJoCo alone: the exported calibrated MJCF at the corrected commands
    # against the nominal MJCF at the program's
    cal = tmp_path / "cal.xml"
    assert main(["export", "--model", str(ARM), "--errors", str(ARM_ERRORS), "--result",
                 str(result), "--out", str(cal)]) == 0  # fmt: skip
    pos_cal, rot_cal = _mujoco_tool(cal, nominal.actuator_names, corrected)
    pos_nom, rot_nom = _mujoco_tool(ARM, nominal.actuator_names, program)
    miss = np.linalg.norm(pos_cal - pos_nom, axis=1)
    assert np.max(miss) < REACH_M
    assert np.max(rotation_angle(np.swapaxes(rot_cal, 1, 2) @ rot_nom)) < REACH_RAD
    # the check can fail: the program's own commands on the calibrated model miss by the
    # identified errors (0.3 mm / 0.05 deg over a metre of arm: tenths of a millimetre)
    pos_raw, _ = _mujoco_tool(cal, nominal.actuator_names, program)
    assert np.sqrt(np.mean(np.sum((pos_raw - pos_nom) ** 2, axis=1))) > 0.05e-3
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["n_written"] == 50 and not side["unreachable"]
    assert side["changes_from_program"]["A1"]["unit"] == "deg"


def _mujoco_model(xml) -> mujoco.MjModel:
    """The MJCF as MuJoCo compiles it; the arm declares no masses (kinematics only), so
    with MuJoCo's own bounds on mass and inertia."""
    spec = mujoco.MjSpec.from_file(str(xml))
    spec.compiler.boundmass, spec.compiler.boundinertia = 1e-3, 1e-6
    return spec.compile()


def _mujoco_smallest_singular_value(xml, actuators, commands):
    """The smallest singular value of the tool site's Jacobian (6, A) (m, rad) of the MJCF
    ``xml`` at each row of ``commands`` (N, A): mj_jacSite, nothing of this project."""
    m = _mujoco_model(xml)
    d = mujoco.MjData(m)
    joints = [m.actuator_trnid[m.actuator(a).id, 0] for a in actuators]
    adr, dof = m.jnt_qposadr[joints], m.jnt_dofadr[joints]
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    out = np.empty(len(commands))
    for i, c in enumerate(commands):
        d.qpos[:] = m.qpos0
        d.qpos[adr] = c
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_jacSite(m, d, jp, jr, m.site("tool").id)
        out[i] = np.linalg.svd(np.vstack([jp, jr])[:, dof], compute_uv=False)[-1]
    return out


def _mujoco_tool(xml, actuators, commands):
    """Tool site positions (N, 3) and rotations (N, 3, 3) of the MJCF ``xml`` with each
    actuator's joint at ``commands`` (N, A) (rad): mj_kinematics, nothing of this project."""
    m = _mujoco_model(xml)
    d = mujoco.MjData(m)
    adr = [m.jnt_qposadr[m.actuator_trnid[m.actuator(a).id, 0]] for a in actuators]
    tool = m.site("tool").id
    pos, rot = np.empty((len(commands), 3)), np.empty((len(commands), 3, 3))
    for i, c in enumerate(commands):
        d.qpos[:] = m.qpos0
        d.qpos[adr] = c
        mujoco.mj_kinematics(m, d)
        pos[i], rot[i] = d.site_xpos[tool], d.site_xmat[tool].reshape(3, 3)
    return pos, rot


def test_a_dataset_is_a_program_and_bad_programs_are_named(calibrated_arm, tmp_path, capsys):
    nominal, data, result, _ = calibrated_arm
    out = tmp_path / "c.csv"
    assert _run(ARM, ARM_ERRORS, result, "--commands", data, "--out", out) == 0
    rows, corrected = _read(out, nominal)
    assert len(rows) == 40  # one row per pose_id, the dataset's other columns ignored
    with data.open() as fh:  # the dataset's own commands, first row of each pose
        first = {}
        for r in csv.DictReader(fh):
            first.setdefault(r["pose_id"], [float(r[f"cmd:{a}"]) for a in nominal.actuator_names])
    assert [r["pose_id"] for r in rows] == list(first)
    program = np.array(list(first.values())) / _file_scale(nominal)
    # the same targets as a plain program: the same corrected commands, to the bit
    plain = _program_csv(tmp_path / "plain.csv", nominal, program, list(first))
    assert _run(ARM, ARM_ERRORS, result, "--commands", plain, "--out", tmp_path / "p.csv") == 0
    assert np.array_equal(_read(tmp_path / "p.csv", nominal)[1], corrected)
    assert np.max(np.abs(corrected - program)) > 0
    capsys.readouterr()
    head = "pose_id," + ",".join(f"cmd:{a}" for a in nominal.actuator_names)
    for text, message in [
        (head.replace(",cmd:A6", "") + "\nt,1,2,3,4,5\n", "missing column(s) ['cmd:A6']"),
        (head + ",cmd:A7\nt,1,2,3,4,5,6,7\n", "'cmd:A7' names no actuator"),
        (head + "\nt,1,2,3,4,5,6\nt,1,2,3,4,5,7\n", "pose_id 't' has other commands"),
        (head + "\nt,1,2,x,4,5,6\n", "'x' is not a number"),
        (head + "\n", "no joint targets"),
    ]:
        bad = tmp_path / "bad.csv"
        bad.write_text(text)
        assert _run(ARM, ARM_ERRORS, result, "--commands", bad, "--out", out) == 2
        assert message in capsys.readouterr().err
    # a target past a stroke is named, the others written (exit 5)
    program = np.zeros((2, 6))
    program[1, 2] = np.radians(75.0)  # A3's range is -155..70 deg
    prog_csv = _program_csv(tmp_path / "p.csv", nominal, program, ["ok", "past"])
    assert _run(ARM, ARM_ERRORS, result, "--commands", prog_csv, "--out", out) == 5
    assert "pose_id past: the program's own command: actuator 'A3' needs 75 deg" in (
        capsys.readouterr().err
    )
    assert [r["pose_id"] for r in _read(out, nominal)[0]] == ["ok"]


def test_a_parallel_machines_program_goes_through_the_identified_gains(tmp_path, capsys):
    """The hexapod with identified leg gains: the corrected commands, through the gains,
    give joint values that put the identified platform where the nominal one is at the
    program (checked on the identified model: the exported MJCF holds no gains yet)."""
    from calib.compensate import load_identified_machine
    from calib.fit import model_from_files
    from twin.parameters import Parameter, ParameterSet

    nominal = Mechanism.from_xml(HEXAPOD)
    base = load_parameter_set(HEXAPOD_ERRORS, nominal.model)
    gains = [Parameter(f"{a}.gain", "actuator_gain", a) for a in nominal.actuator_names]
    params = ParameterSet([*base.parameters, *gains], nominal.model)
    geometry = load_values(ROOT / "scenarios/truth/hexapod_table2.toml", base)
    ppm = np.array([300.0, -200.0, 150.0, 0.0, 500.0, -400.0]) * 1e-6
    result = result_file(
        tmp_path / "r.json", nominal.name, params, np.concatenate([geometry, ppm]), added=gains
    )
    _, program = random_poses(nominal, 20, np.random.default_rng(33))
    prog_csv = _program_csv(tmp_path / "program.csv", nominal, program)
    out = tmp_path / "corrected.csv"
    assert _run(HEXAPOD, HEXAPOD_ERRORS, result, "--commands", prog_csv, "--out", out) == 0
    _, corrected = _read(out, nominal)
    machine = load_identified_machine(model_from_files(str(HEXAPOD), str(HEXAPOD_ERRORS)), result)
    joints = machine.joints_for_commands(corrected)
    assert not np.allclose(joints[:, [0, 1, 2, 4, 5]], corrected[:, [0, 1, 2, 4, 5]], atol=1e-9)
    intent = forward_batch(nominal, program)
    got = forward_batch(machine.mechanism, joints, check_stroke=False)
    assert np.max(np.linalg.norm(got.tool_position - intent.tool_position, axis=1)) < REACH_M
    turn = rotation_angle(np.swapaxes(got.tool_rotation, 1, 2) @ intent.tool_rotation)
    assert np.max(turn) < REACH_RAD
    # without the gains the same geometry asks for other commands: the gains were applied
    plain = result_file(tmp_path / "g.json", nominal.name, base, geometry)
    out_plain = tmp_path / "plain.csv"
    assert _run(HEXAPOD, HEXAPOD_ERRORS, plain, "--commands", prog_csv, "--out", out_plain) == 0
    _, without = _read(out_plain, nominal)
    zero = machine.model.joint_zeros(machine.values)
    # the same joint values (same geometry), reached by commands scaled back by the gains
    assert np.allclose((without - zero), (corrected - zero) * (1 + ppm), rtol=0, atol=1e-12)
    assert "program targets" in capsys.readouterr().out


UR10_DH = """# convention: standard
# UR10-like: the published nominal DH of a UR10, every joint +-360 deg as on the robot
joint,alpha_deg,a_mm,d_mm,theta_deg,min_deg,max_deg,home_deg
J1,90,0,127.3,0,-360,360,0
J2,0,-612,0,0,-360,360,-90
J3,0,-572.3,0,0,-360,360,90
J4,90,0,163.941,0,-360,360,-90
J5,-90,0,115.7,0,-360,360,-90
J6,0,0,92.2,0,-360,360,0
site,x_mm,y_mm,z_mm
tool,0,0,0
target_1,0,0,0
"""
# joint targets of a program far from home (shoulder pan up to 150 deg away)
UR10_PROGRAM_DEG = [
    [120, -60, 100, -130, -80, 30],
    [-100, -110, -70, -20, 95, -40],
    [150, -45, 60, -100, -90, 10],
    [95, -120, 110, -80, -60, 200],
    [-135, -80, -95, -15, 70, 0],
]


def test_position_only_poses_keep_the_programs_branch_with_a_seed(tmp_path, capsys):
    table = tmp_path / "ur10.dh.csv"
    table.write_text(UR10_DH)
    assert dh_table_main([str(table), "--name", "ur10", "--out-dir", str(tmp_path)]) == 0
    model, errors = tmp_path / "ur10.xml", tmp_path / "ur10.params.toml"
    nominal = Mechanism.from_xml(model)
    params = load_parameter_set(errors, nominal.model)
    values = plausible_values(params, np.random.default_rng(34))
    result = result_file(tmp_path / "r.json", nominal.name, params, values)
    program = np.radians(np.array(UR10_PROGRAM_DEG, dtype=float))
    prog_csv = _program_csv(tmp_path / "program.csv", nominal, program)
    # positions a few mm from where the program takes the tool, no orientation
    wanted = forward_batch(nominal, program).tool_position + np.array([3.0, -2.0, 4.0]) * 1e-3
    poses = tmp_path / "poses.csv"
    poses.write_text(
        "pose_id,x_mm,y_mm,z_mm\n"
        + "".join(f"p{k},{x},{y},{z}\n" for k, (x, y, z) in enumerate(wanted * 1e3))
    )
    out = tmp_path / "c.csv"
    pan = np.degrees(program[:, 0])
    # without a seed: the nominal home's orientation, solved from home: other branches
    assert _run(model, errors, result, "--poses", poses, "--out", out) == 0
    assert "no seed" in capsys.readouterr().out
    _, unseeded = _read(out, nominal)
    assert np.max(np.abs(np.degrees(unseeded[:, 0]) - pan)) > 90
    # with the program as seeds: each pose on its nearest target's branch, within a degree
    assert _run(model, errors, result, "--poses", poses, "--commands", prog_csv, "--out", out) == 0
    assert "seed: the nearest target of" in capsys.readouterr().out
    rows, seeded = _read(out, nominal)
    assert [r["seed"] for r in rows] == [f"t{k}" for k in range(5)]
    assert np.max(np.abs(seeded - program)) < JOINT_RAD
    reached = forward_batch(nominal.with_model(params.inject(nominal.model, values)), seeded)
    assert np.max(np.abs(reached.tool_position - wanted)) < 1e-9
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["seed"]["source"] == "program" and side["seed"]["per_pose"]["p3"] == "t3"
    # one --seed (the target 3's commands, by name) for its pose
    seed = ",".join(
        f"{a}={v}" for a, v in zip(nominal.actuator_names, UR10_PROGRAM_DEG[3], strict=True)
    )
    one = tmp_path / "one.csv"
    one.write_text("pose_id,x_mm,y_mm,z_mm\n" + "p3,{},{},{}\n".format(*(wanted[3] * 1e3)))
    assert _run(model, errors, result, "--poses", one, "--seed", seed, "--out", out) == 0
    assert f"seed: --seed {seed}" in capsys.readouterr().out
    _, by_seed = _read(out, nominal)
    assert np.max(np.abs(by_seed[0] - seeded[3])) < 1e-9  # the same solution
    for extra, message in [
        (["--seed", "J1=0,J2=-90"], "no value for ['J3', 'J4', 'J5', 'J6']"),
        (["--seed", "0,1,2"], "3 values for 6 actuators"),
        (["--seed", "J1=0,J2=-90,J3=90,J4=-90,J5=-90,J7=0"], "'J7' is no actuator"),
        (["--seed", "0,0,0,0,0,0", "--commands", prog_csv], "give one"),
    ]:
        assert _run(model, errors, result, "--poses", one, *extra, "--out", out) == 2
        assert message in capsys.readouterr().err


def _refused(path, params, values, code, message):
    result_file(path, "arm6r", params, values)
    data = json.loads(path.read_text())
    data["verdict"] = {"status": "poor_fit", "exit_code": code, "message": message, "hints": []}
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(("code", "message"), [
    (3, "FAILED: the fit did not converge (iteration limit)"),
    (4, "FAILED: the data look wrong; residual 12 mm"),
])  # fmt: skip
def test_compensate_and_export_of_a_refused_result_exit_with_identifys_code(
    tmp_path, capsys, code, message
):
    nominal = Mechanism.from_xml(ARM)
    params = load_parameter_set(ARM_ERRORS, nominal.model)
    values = plausible_values(params, np.random.default_rng(35))
    result = _refused(tmp_path / "r.json", params, values, code, message)
    prog_csv = _program_csv(tmp_path / "p.csv", nominal, np.zeros((1, 6)))
    out, cal = tmp_path / "c.csv", tmp_path / "cal.xml"
    export = ["export", "--model", str(ARM), "--errors", str(ARM_ERRORS), "--result", str(result)]
    assert _run(ARM, ARM_ERRORS, result, "--commands", prog_csv, "--out", out) == code
    err = capsys.readouterr().err
    assert f"REFUSED RESULT: identify refused {result} (exit {code}): {message}" in err
    assert "--force" in err and not out.exists() and not out.with_suffix(".json").exists()
    assert main([*export, "--out", str(cal)]) == code
    assert f"(exit {code}): {message}" in capsys.readouterr().err and not cal.exists()
    # --force: they proceed and say so
    assert _run(ARM, ARM_ERRORS, result, "--commands", prog_csv, "--out", out, "--force") == 0
    assert f"--force: compensate of {result}, a result identify refused (exit {code})" in (
        capsys.readouterr().err
    )
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["forced"] is True and side["identify_exit_code"] == code
    assert main([*export, "--out", str(cal), "--force"]) == 0
    assert f"--force: export of {result}" in capsys.readouterr().err and cal.is_file()
    # an accepted result needs no --force
    ok = result_file(tmp_path / "ok.json", "arm6r", params, values)
    assert _run(ARM, ARM_ERRORS, ok, "--commands", prog_csv, "--out", out) == 0
    assert "REFUSED" not in capsys.readouterr().err


def test_options_that_do_not_go_together_are_refused(tmp_path, capsys):
    nominal = Mechanism.from_xml(ARM)
    params = load_parameter_set(ARM_ERRORS, nominal.model)
    result = result_file(tmp_path / "r.json", "arm6r", params, np.zeros(len(params)))
    prog_csv = _program_csv(tmp_path / "p.csv", nominal, np.zeros((1, 6)))
    out = tmp_path / "c.csv"
    for extra, message in [
        ([], "needs --commands program.csv"),
        (["--commands", prog_csv, "--seed", "0,0,0,0,0,0"], "give --poses with it"),
        (["--commands", prog_csv, "--frame", "tracker"], "--frame is the frame of --poses"),
    ]:
        assert _run(ARM, ARM_ERRORS, result, *extra, "--out", out) == 2
        assert message in capsys.readouterr().err
        assert not out.exists()
