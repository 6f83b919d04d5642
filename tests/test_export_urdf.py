"""calib export --urdf-out: the calibrated URDF of a model generated from a URDF.

models/arm6r.urdf becomes a model (twin.formats.from_urdf), errors of a built arm (and two
actuator gains, which a URDF cannot hold) make a result, and export writes the URDF with the
identified geometry and joint zeros in its joint origins. Read back by the project's own URDF
import, its forward kinematics equals the identified model's to 1e-9 m at the same joint
values; pinocchio's own URDF parser agrees; the gains and the reflector offsets are in the
sidecar and the header.
"""

from __future__ import annotations

import json
import shutil
from types import SimpleNamespace

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from to_machine_support import MODELS, plausible_values, result_file

from calib.cli.commands import main
from calib.compensate.identified_machine import load_identified_machine
from calib.compensate.model_export import probe_commands
from calib.fit import model_from_files
from twin.formats.from_urdf import convert
from twin.formats.parameter_file import load_parameter_set
from twin.formats.urdf_values import rpy_of
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rpy


def body(m: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("urdf")
    shutil.copy(MODELS / "arm6r.urdf", tmp / "arm6r.urdf")
    xml, toml, _ = convert(tmp / "arm6r.urdf", ["target_1=link6@50,0,110"], "link6@0,0,120", None)
    model = tmp / "arm6r.xml"
    model.write_text(xml)
    toml += "".join(
        f'\n[[parameter]]\nname = "{a}.gain"\nkind = "actuator_gain"\nelement = "{a}"\n'
        for a in ("A2", "A3")
    )
    errors = tmp / "arm6r.params.toml"
    errors.write_text(toml)
    nominal = Mechanism.from_xml(model)
    params = load_parameter_set(errors, nominal.model)
    values = plausible_values(params, np.random.default_rng(9))
    values[params.is_gain] = [300e-6, -150e-6]
    result = result_file(tmp / "r.json", nominal.name, params, values)
    out, urdf_out = tmp / "arm6r_cal.xml", tmp / "arm6r_cal.urdf"
    args = ["export", "--model", str(model), "--errors", str(errors), "--result", str(result)]
    code = main([*args, "--out", str(out), "--urdf-out", str(urdf_out)])  # URDF from the header
    return SimpleNamespace(code=code, model=model, errors=errors, result=result, urdf=urdf_out)


def test_calibrated_urdf_reads_back_as_the_identified_model(exported, capsys):
    model, errors, result, urdf_out = (
        exported.model,
        exported.errors,
        exported.result,
        exported.urdf,
    )
    assert exported.code == 0
    machine = load_identified_machine(model_from_files(model, errors), result)
    back = convert(urdf_out, ["target_1=link6"], None, None)[2]  # the project's URDF import
    mech, joints = machine.mechanism, probe_commands(machine.nominal)
    da, db = mujoco.MjData(mech.model), mujoco.MjData(back.model)
    links = [f"link{i}" for i in range(1, 7)]
    worst = 0.0
    for q in joints:  # a serial arm: its configuration is its joint values
        da.qpos[:], db.qpos[:] = q, q
        mujoco.mj_kinematics(mech.model, da)
        mujoco.mj_kinematics(back.model, db)
        for link in links:
            ia, ib = (
                mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, link)
                for m in (mech.model, back.model)
            )
            worst = max(worst, float(np.max(np.abs(da.xpos[ia] - db.xpos[ib]))))
            assert np.max(np.abs(da.xmat[ia] - db.xmat[ib])) < 1e-12
    assert worst < 1e-9  # every link's frame, as the export's own check of targets and tool
    side = json.loads(urdf_out.with_name("arm6r_cal.urdf.calibration.json").read_text())
    kinds = {m["kind"] for m in side["not_held"]}
    assert kinds == {"actuator_gain", "site_pos"}  # a URDF has no actuators and no sites
    names = [m["name"] for m in side["not_held"]]
    assert "A2.gain" in names and "A3.gain" in names
    assert "A2.gain 300 ppm" in urdf_out.read_text()


def test_pinocchio_reads_the_calibrated_urdf_as_the_identified_model(exported):
    model, errors, result, urdf_out = (
        exported.model,
        exported.errors,
        exported.result,
        exported.urdf,
    )
    machine = load_identified_machine(model_from_files(model, errors), result)
    pm = pin.buildModelFromUrdf(str(urdf_out))
    data = pm.createData()
    mech = machine.mechanism
    m = mech.model
    link6 = pm.getFrameId("link6")
    joints = probe_commands(machine.nominal)
    fk = forward_batch(mech, joints)
    body = int(m.site_bodyid[mech.tool_site])
    for q, qpos in zip(joints, fk.qpos, strict=True):
        order = [pm.joints[pm.getJointId(f"A{i}")].idx_q for i in range(1, 7)]
        qp = np.zeros(pm.nq)
        qp[order] = q
        pin.framesForwardKinematics(pm, data, qp)
        d = mujoco.MjData(m)
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        assert np.max(np.abs(data.oMf[link6].translation - d.xpos[body])) < 1e-9
        assert np.max(np.abs(data.oMf[link6].rotation - d.xmat[body].reshape(3, 3))) < 1e-12


def test_rpy_of_inverts_matrix_from_rpy_at_and_near_a_pitch_of_90_deg():
    rng = np.random.default_rng(1)
    for pitch in (np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-7, 0.3):
        rpy = np.array([rng.uniform(-3, 3), pitch, rng.uniform(-3, 3)])
        r = matrix_from_rpy(rpy)
        assert np.max(np.abs(matrix_from_rpy(rpy_of(r)) - r)) < 4e-16 * 8


def test_a_urdf_that_is_not_the_models_is_refused(exported, tmp_path, capsys):
    model, errors, result = exported.model, exported.errors, exported.result
    other = tmp_path / "other.urdf"
    other.write_text(
        (MODELS / "arm6r.urdf").read_text().replace('xyz="0.45 0 0"', 'xyz="0.46 0 0"')
    )
    args = ["export", "--model", str(model), "--errors", str(errors), "--result", str(result)]
    out = tmp_path / "x.xml"
    code = main(
        [*args, "--out", str(out), "--urdf-out", str(tmp_path / "x.urdf"), "--urdf", str(other)]
    )
    assert code == 2
    assert "is not the URDF the model was generated from" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "x.urdf").exists()
