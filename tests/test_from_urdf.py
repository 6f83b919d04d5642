"""URDF in (python -m twin.formats.from_urdf) and the complete error model (python -m
twin.formats.error_model).

The URDF of models/arm6r gives arm6r.xml's forward kinematics to 1e-9 m; fixed, continuous
and prismatic joints, inertials and meshes are read; a generated error model spans every
hand-written one's effect on the arm, the hexapod and the polisher; bad input is named and
nothing is written.
"""

from __future__ import annotations

import numpy as np
import pytest
from to_machine_support import MODELS

from calib.compensate.model_export import kinematics_difference, probe_commands
from calib.fit.model import CalibrationModel
from twin.formats.error_model import error_parameters
from twin.formats.error_model import main as error_model_main
from twin.formats.from_urdf import main as from_urdf_main
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism

ARM_TOOL = ["--target", "target_1=link6@50,0,110", "--tool", "link6@0,0,120"]


def test_urdf_of_the_arm_has_the_arm_models_kinematics(tmp_path, capsys):
    out = tmp_path / "out"
    assert from_urdf_main([str(MODELS / "arm6r.urdf"), *ARM_TOOL, "--out-dir", str(out)]) == 0
    assert "6 actuators ['A1', 'A2', 'A3', 'A4', 'A5', 'A6']" in capsys.readouterr().out
    arm = Mechanism.from_xml(MODELS / "arm6r.xml")
    imported = Mechanism.from_xml(out / "arm6r.xml")
    assert imported.name == "arm6r" and imported.target_names == ("target_1",)
    lo, hi = arm.actuator_range.T
    commands = np.random.default_rng(31).uniform(lo, hi, (200, arm.n_actuators))
    check = kinematics_difference(arm, imported, commands)
    assert check.max_position_m < 1e-9 and check.max_rotation_rad < 1e-9
    assert np.allclose(imported.actuator_range, arm.actuator_range, atol=1e-11)
    params = load_parameter_set(out / "arm6r.params.toml", imported.model)
    assert params.names == error_parameters(imported).names and len(params) == 39


URDF = """<?xml version="1.0"?>
<robot name="rig">
  <link name="base_link"><visual><geometry><mesh filename="package://rig/base.stl"/></geometry></visual></link>
  <link name="carriage">
    <inertial><origin xyz="0 0 0.05"/><mass value="3.5"/>
      <inertia ixx="0.02" iyy="0.03" izz="0.04" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><mesh filename="package://rig/carriage.stl"/></geometry></collision>
  </link>
  <link name="arm"/>
  <link name="tool0"/>
  <joint name="slide" type="prismatic"><parent link="base_link"/><child link="carriage"/>
    <origin xyz="0 0 0.2" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.3" upper="0.4" effort="1" velocity="1"/></joint>
  <joint name="spin" type="continuous"><parent link="carriage"/><child link="arm"/>
    <origin xyz="0 0.1 0.05" rpy="0.3 -0.2 0.1"/><axis xyz="0 0 1"/></joint>
  <joint name="flange" type="fixed"><parent link="arm"/><child link="tool0"/>
    <origin xyz="0.25 0 0" rpy="0 1.5707963267948966 0"/></joint>
</robot>
"""


def test_fixed_continuous_prismatic_joints_inertials_and_meshes(tmp_path, capsys):
    urdf = tmp_path / "rig.urdf"
    urdf.write_text(URDF)
    args = [str(urdf), "--target", "target_a=tool0@0,20,0", "--target", "target_b=tool0"]
    out = tmp_path / "out"
    assert from_urdf_main([*args, "--tool", "tool0@0,0,30,0,0,90", "--out-dir", str(out)]) == 0
    mech = Mechanism.from_xml(out / "rig.xml")
    m = mech.model
    assert mech.actuator_names == ("slide", "spin") and list(mech.actuator_is_slide) == [
        True,
        False,
    ]
    assert np.isinf(mech.actuator_range[1]).all()  # continuous: no range
    # the carriage's inertial is kept; 'arm' and 'tool0' declare none (MuJoCo's bound)
    assert np.isclose(m.body_mass[m.body("carriage").id], 3.5) and mech.masses_defaulted
    # the tool frame at 30 mm along tool0's z, turned 90 deg: tool0 is 0.25 m along arm's x
    sol = mech.data
    import mujoco

    mech.data.qpos[:] = [0.1, 0.7]
    mujoco.mj_kinematics(m, sol)
    tool0 = m.body("tool0").id
    expect = sol.xpos[tool0] + sol.xmat[tool0].reshape(3, 3) @ [0, 0, 0.03]
    assert np.allclose(sol.site_xpos[mech.tool_site], expect, atol=1e-12)
    params = load_parameter_set(out / "rig.params.toml", m)
    assert "slide.zero" in params.names and "spin.zero" in params.names
    assert "carriage.dx" not in params.names  # the shift along the slide is its zero


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--target", "target_1=link7@0,0,1"], "has no link 'link7' (did you mean 'link6'?)"),
        (["--target", "target_1=link6@1,2"], "is not 3 numbers"),
        (["--target", "target_1=link6@1,2,x"], "is not 3 numbers"),
        (["--target", "reflector=link6"], "a reflector's name is target_"),
        (["--target", "target_1=link6", "--tool", "link6@1,2,3,4"], "is not 3 or 6 numbers"),
        ([], "give at least one reflector"),
    ],
)
def test_bad_urdf_input_is_named_and_nothing_written(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    assert from_urdf_main([str(MODELS / "arm6r.urdf"), *args, "--out-dir", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_mimic_joint_or_a_file_that_is_no_urdf_is_refused(tmp_path, capsys):
    mimic = tmp_path / "m.urdf"
    mimic.write_text(
        URDF.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 1"/><mimic joint="slide"/>')
    )
    out = tmp_path / "out"
    assert from_urdf_main([str(mimic), "--target", "target_1=arm", "--out-dir", str(out)]) == 2
    assert "mimics another joint" in capsys.readouterr().err
    assert (
        from_urdf_main([str(MODELS / "arm6r.xml"), "--target", "target_1=x", "--out-dir", str(out)])
        == 2
    )
    assert "not a URDF" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(
    ("xml", "toml"),
    [
        ("arm6r.xml", "arm6r.params.toml"),
        ("arm6r_3targets.xml", "arm6r_3targets.params.toml"),
        ("hexapod_rrrprr.xml", "hexapod_rrrprr.params.toml"),
        ("polisher.xml", "polisher.params.toml"),
    ],
)
def test_the_generated_error_model_spans_the_hand_written_one(xml, toml):
    """Every hand-written parameter's effect on the readings is a combination of the
    generated parameters' (at commands spread over the workspace): nothing is missing."""
    nominal = Mechanism.from_xml(MODELS / xml)
    hand = CalibrationModel(nominal, load_parameter_set(MODELS / toml, nominal.model))
    generated = CalibrationModel(nominal, error_parameters(nominal))
    commands = probe_commands(nominal, 12)

    def jacobian(model):
        zero = np.zeros(model.n_parameters)
        return model.jacobian(zero, model.predict(zero, commands))

    jh, jg = jacobian(hand), jacobian(generated)
    u, s, _ = np.linalg.svd(jg, full_matrices=False)
    basis = u[:, s > s[0] * 1e-10]
    norms = np.linalg.norm(jh, axis=0)
    left = np.linalg.norm(jh - basis @ (basis.T @ jh), axis=0)
    assert np.all(left <= 1e-8 * max(norms.max(), 1e-300) + 1e-8 * norms)


def test_error_model_command_writes_beside_the_model_and_keeps_a_users_file(tmp_path, capsys):
    model = tmp_path / "arm6r.xml"
    model.write_text((MODELS / "arm6r.xml").read_text())
    assert error_model_main([str(model)]) == 0
    written = tmp_path / "arm6r.params.toml"
    assert "wrote" in capsys.readouterr().out and written.is_file()
    written.write_text("# mine\n")
    assert error_model_main([str(model)]) == 2
    assert "exists" in capsys.readouterr().err and written.read_text() == "# mine\n"
