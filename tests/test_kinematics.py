"""Closed-chain kinematics: closure, round trips, batch = single, Jacobians, clear errors."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

import twin.kinematics.batch as kinematics_batch
import twin.kinematics.single_pose as kinematics
from twin.exceptions import ClosureError, ModelError, WorkspaceError
from twin.kinematics.batch import forward_batch
from twin.kinematics.closure import (
    closure_jacobian,
    closure_residual,
    update_kinematics,
)
from twin.kinematics.single_pose import forward, inverse, pose_to_frame
from twin.mechanism import Mechanism
from twin.rotations import rotvec_from_matrix, rpy_from_matrix
from twin.workspace import random_poses

HEXAPOD_XML = Path(__file__).resolve().parent.parent / "models" / "hexapod_rrrprr.xml"


@pytest.fixture(scope="module")
def reachable(hexapod):
    """20 seeded random poses of the Table 3 box that keep every limb in its stroke."""
    return random_poses(hexapod, 20, np.random.default_rng(20190))


def _perturbed(mech: Mechanism, qpos: np.ndarray, rng: np.random.Generator, size: float):
    """A configuration near ``qpos``: every dof moved by up to ``size`` (m or rad)."""
    q = qpos.copy()
    mujoco.mj_integratePos(mech.model, q, rng.uniform(-size, size, mech.model.nv), 1.0)
    return q


# ----------------------------------------------------------------------------- forward
def test_forward_closes_every_loop(hexapod, reachable):
    _, commands = reachable
    for c in commands:
        sol = forward(hexapod, c)
        assert sol.residual < 1e-12
        update_kinematics(hexapod, sol.qpos)  # recompute independently of the solver
        assert np.max(np.abs(closure_residual(hexapod))) < 1e-12
        np.testing.assert_array_equal(sol.actuators, c)  # actuators are held, not solved


def test_inverse_then_forward_recovers_the_pose(hexapod, reachable):
    poses, commands = reachable
    for pose, c in zip(poses, commands, strict=True):
        sol = forward(hexapod, c)
        r_cmd, p_cmd = pose_to_frame(pose)
        np.testing.assert_allclose(sol.tool_position, p_cmd, rtol=0, atol=1e-11)
        assert np.linalg.norm(rotvec_from_matrix(sol.tool_rotation @ r_cmd.T)) < 1e-11


def test_forward_then_inverse_recovers_the_commands(hexapod, reachable):
    """Commands not produced by inverse kinematics: perturb each limb by up to 1 mm."""
    _, commands = reachable
    rng = np.random.default_rng(7)
    lo, hi = hexapod.actuator_range[:, 0], hexapod.actuator_range[:, 1]
    for c in commands[:10]:
        c2 = np.clip(c + rng.uniform(-1e-3, 1e-3, 6), lo, hi)
        sol = forward(hexapod, c2)
        pose = np.concatenate([sol.tool_position, rpy_from_matrix(sol.tool_rotation)])
        back = inverse(hexapod, pose)
        np.testing.assert_allclose(back.actuators, c2, rtol=0, atol=1e-11)
        np.testing.assert_allclose(back.targets, sol.targets, rtol=0, atol=1e-11)


def test_home_keyframe_is_a_fixed_point(hexapod):
    home = hexapod.home_qpos
    sol = forward(hexapod, home[hexapod.actuator_qpos])
    np.testing.assert_allclose(sol.qpos, home, atol=1e-11)
    np.testing.assert_allclose(sol.tool_position, [0, 0, 0.220], atol=1e-11)
    # targets: 100 mm circle at 90, 210, 330 deg, 15 mm above the platform frame
    a = np.radians([90.0, 210.0, 330.0])
    expected = np.stack([0.1 * np.cos(a), 0.1 * np.sin(a), np.full(3, 0.235)], axis=1)
    np.testing.assert_allclose(sol.targets, expected, atol=1e-11)


# ----------------------------------------------------------------------------- batch
@pytest.fixture(scope="module")
def fifty(hexapod):
    return random_poses(hexapod, 50, np.random.default_rng(50))[1]


@pytest.mark.parametrize("nthread", [1, 2])
def test_batch_equals_single_across_chunks(hexapod, fifty, monkeypatch, nthread):
    monkeypatch.setattr(kinematics_batch, "CHUNK", 16)  # 16 + 16 + 16 + 2 poses
    batch = forward_batch(hexapod, fifty, nthread=nthread)
    assert batch.targets.shape == (50, 3, 3)
    assert np.all(batch.residual < 1e-12)
    for k, c in enumerate(fifty):
        single = forward(hexapod, c)
        np.testing.assert_allclose(batch.targets[k], single.targets, rtol=0, atol=1e-12)
        np.testing.assert_allclose(batch.tool_position[k], single.tool_position, rtol=0, atol=1e-12)
        np.testing.assert_allclose(batch.tool_rotation[k], single.tool_rotation, atol=1e-12)
        np.testing.assert_array_equal(batch.qpos[k, hexapod.actuator_qpos], c)


def test_batch_threads_agree(hexapod, fifty, monkeypatch):
    monkeypatch.setattr(kinematics_batch, "CHUNK", 16)
    one = forward_batch(hexapod, fifty, nthread=1)
    two = forward_batch(hexapod, fifty, nthread=2)
    np.testing.assert_allclose(one.targets, two.targets, rtol=0, atol=1e-14)
    np.testing.assert_allclose(one.qpos, two.qpos, rtol=0, atol=1e-12)


def test_batch_warm_start_gives_the_same_answer(hexapod, fifty):
    cold = forward_batch(hexapod, fifty[:8])
    warm = forward_batch(hexapod, fifty[:8], start=cold.qpos)
    np.testing.assert_allclose(warm.targets, cold.targets, rtol=0, atol=1e-12)
    assert warm.iterations <= 1


# ----------------------------------------------------------------------------- Jacobians
def _fd_closure_jacobian(mech: Mechanism, qpos: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    nv = mech.model.nv
    fd = np.zeros((mech.n_closure, nv))
    for k in range(nv):
        out = []
        for sign in (1.0, -1.0):
            q = qpos.copy()
            dq = np.zeros(nv)
            dq[k] = sign * eps
            mujoco.mj_integratePos(mech.model, q, dq, 1.0)
            update_kinematics(mech, q)
            out.append(closure_residual(mech))
        fd[:, k] = (out[0] - out[1]) / (2 * eps)
    return fd


def _position_rows(mech: Mechanism) -> np.ndarray:
    rows, start = [], 0
    for c in mech.closures:
        rows += [start, start + 1, start + 2]
        start += c.size
    return np.array(rows)


def test_closure_jacobian_at_a_closed_configuration(hexapod, reachable):
    q = forward(hexapod, reachable[1][3]).qpos
    update_kinematics(hexapod, q)
    jac = closure_jacobian(hexapod)
    assert jac.shape == (36, 42)
    fd = _fd_closure_jacobian(hexapod, q)
    assert np.max(np.abs(fd - jac)) < 1e-6 * np.max(np.abs(jac))


def test_closure_jacobian_position_rows_anywhere(hexapod, reachable):
    q = _perturbed(hexapod, forward(hexapod, reachable[1][5]).qpos, np.random.default_rng(3), 0.05)
    update_kinematics(hexapod, q)
    assert np.max(np.abs(closure_residual(hexapod))) > 1e-3  # really not closed
    jac = closure_jacobian(hexapod)
    fd = _fd_closure_jacobian(hexapod, q)
    rows = _position_rows(hexapod)
    assert np.max(np.abs(fd[rows] - jac[rows])) < 1e-6 * np.max(np.abs(jac[rows]))


# ----------------------------------------------------------------------------- user errors
def test_command_outside_the_stroke_names_the_actuator(hexapod):
    with pytest.raises(
        WorkspaceError, match=r"actuator 'leg3' command 300 mm .*outside its stroke \[195, 265\] mm"
    ):
        forward(hexapod, np.array([0.23, 0.23, 0.30, 0.23, 0.23, 0.23]))
    with pytest.raises(WorkspaceError, match=r"actuator 'leg5' command 190 mm .*\[195, 265\] mm"):
        forward(hexapod, np.array([0.23, 0.23, 0.23, 0.23, 0.19, 0.23]))


def test_batch_command_outside_the_stroke_names_pose_and_actuator(hexapod, reachable):
    commands = reachable[1][:4].copy()
    commands[2, 5] = 0.27
    with pytest.raises(WorkspaceError, match=r"pose 2: actuator 'leg6' command 270 mm"):
        forward_batch(hexapod, commands)


def test_non_finite_command_raises(hexapod):
    with pytest.raises(WorkspaceError, match=r"non-finite actuator command"):
        forward(hexapod, np.array([0.23] * 5 + [np.nan]))


def test_wrong_number_of_commands_raises(hexapod):
    with pytest.raises(WorkspaceError, match=r"expected 6 actuator commands .*'leg1'"):
        forward(hexapod, np.full(5, 0.23))
    with pytest.raises(WorkspaceError, match=r"expected 6 actuator commands"):
        forward(hexapod, np.full(7, 0.23))
    with pytest.raises(WorkspaceError, match=r"expected 6 actuator commands"):
        forward_batch(hexapod, np.full((3, 5), 0.23))


def test_unreachable_pose_raises(hexapod):
    with pytest.raises((WorkspaceError, ClosureError), match=r"not reachable.*'leg1'"):
        inverse(hexapod, np.array([0.0, 0.0, 0.5, 0.0, 0.0, 0.0]))
    with pytest.raises(WorkspaceError, match=r"6 finite numbers"):
        inverse(hexapod, np.array([0.0, 0.0, 0.22]))
    with pytest.raises(WorkspaceError, match=r"6 finite numbers"):
        inverse(hexapod, np.array([0.0, 0.0, np.inf, 0.0, 0.0, 0.0]))


def test_unreachable_pose_without_stroke_check_returns_the_long_limbs(hexapod):
    """Without the stroke check the same pose solves, with limbs beyond 265 mm."""
    sol = inverse(hexapod, np.array([0.0, 0.0, 0.5, 0.0, 0.0, 0.0]), check_stroke=False)
    assert sol.residual < 1e-12
    assert np.all(sol.actuators > 0.265)
    np.testing.assert_allclose(sol.actuators, sol.actuators[0], rtol=0, atol=1e-12)  # symmetric


def test_closure_solve_that_does_not_converge(hexapod, reachable, monkeypatch):
    home = hexapod.home_qpos[hexapod.actuator_qpos]
    far = reachable[1][np.argmax(np.abs(reachable[1] - home).max(axis=1))]
    assert np.max(np.abs(far - home)) > 0.01  # more than 10 mm from home on some limb
    monkeypatch.setattr(kinematics, "MAX_ITER", 1)
    with pytest.raises(ClosureError, match=r"forward kinematics of 'hexapod_rrrprr' did not conv"):
        forward(hexapod, far)
    with pytest.raises(ClosureError, match=r"inverse kinematics .* did not converge"):
        inverse(hexapod, reachable[0][0])


def test_batch_closure_solve_that_does_not_converge(hexapod, reachable, monkeypatch):
    monkeypatch.setattr(kinematics_batch, "MAX_ITER", 1)
    with pytest.raises(ClosureError, match=r"4 of 4 poses did not close \(first: pose 0"):
        forward_batch(hexapod, reachable[1][:4])


# ----------------------------------------------------------------------------- MJCF errors
SLIDER = """<mujoco model="slider">
  <custom>
    <numeric name="workspace_min" data="WORKSPACE_MIN"/>
    <numeric name="workspace_max" data="1 1 1 1 1 1"/>
  </custom>
  <worldbody>
    <body name="carriage">
      <joint name="slide" type="slide" axis="1 0 0" range="-0.1 0.1"/>
      <geom size="0.01"/>
      <site name="carriage_end" pos="0 0 0.05"/>
    </body>
    <body name="plate" pos="0 0 0.05">
      <freejoint/>
      <geom size="0.01"/>
      <site name="plate_joint"/>
      <site name="tool" pos="0 0 0.02"/>
      <site name="target_1" pos="0.01 0 0.02"/>
    </body>
  </worldbody>
  <equality>
    <weld name="closure" site1="carriage_end" site2="plate_joint"/>
  </equality>
  <actuator>
    <position name="drive" joint="slide"/>
  </actuator>
</mujoco>"""


def _slider() -> str:
    return SLIDER.replace("WORKSPACE_MIN", "-1 -1 -1 -1 -1 -1")


def _edit(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new)


def test_minimal_closed_chain_loads_and_solves():
    mech = Mechanism.from_xml_string(_slider())
    assert mech.name == "slider"
    assert mech.actuator_names == ("drive",)
    assert mech.n_closure == 6 and len(mech.free_dofs()) == 6
    sol = forward(mech, np.array([0.03]))
    np.testing.assert_allclose(sol.targets, [[0.04, 0.0, 0.07]], atol=1e-12)
    np.testing.assert_allclose(inverse(mech, np.array([-0.02, 0, 0.07, 0, 0, 0])).actuators, -0.02)


def test_mjcf_without_actuators():
    xml = _edit(_slider(), '<position name="drive" joint="slide"/>', "")
    with pytest.raises(ModelError, match=r"model 'slider' has no <actuator>"):
        Mechanism.from_xml_string(xml)
    # with a keyframe, MuJoCo itself would only complain of the keyframe's ctrl size
    keyed = xml.replace("</mujoco>", '<keyframe><key name="home" ctrl="0.03"/></keyframe></mujoco>')
    with pytest.raises(ModelError, match=r"model 'slider' has no <actuator>: nothing to command"):
        Mechanism.from_xml_string(keyed)


def test_mjcf_actuator_problems():
    unnamed = _edit(_slider(), 'name="drive" ', "")
    with pytest.raises(ModelError, match=r"actuator 0 of 'slider' has no name"):
        Mechanism.from_xml_string(unnamed)
    on_site = _edit(_slider(), 'joint="slide"/>', 'site="carriage_end" gear="1 0 0 0 0 0"/>')
    with pytest.raises(ModelError, match=r"does not drive a joint"):
        Mechanism.from_xml_string(on_site)


def test_mjcf_without_target_sites():
    xml = _edit(_slider(), 'name="target_1"', 'name="reflector_1"')
    with pytest.raises(ModelError, match=r"no tracker target sites \('target_\*'\)"):
        Mechanism.from_xml_string(xml)


def test_mjcf_without_tool_site():
    xml = _edit(_slider(), 'name="tool"', 'name="tcp"')
    with pytest.raises(ModelError, match=r"has no 'tool' site"):
        Mechanism.from_xml_string(xml)


@pytest.mark.parametrize(
    "closure",
    [
        '<weld name="closure" body1="carriage" body2="plate"/>',
        '<connect name="closure" body1="carriage" body2="plate" anchor="0 0 0.05"/>',
    ],
    ids=["weld", "connect"],
)
def test_mjcf_with_body_based_closure(closure):
    xml = _edit(
        _slider(), '<weld name="closure" site1="carriage_end" site2="plate_joint"/>', closure
    )
    with pytest.raises(ModelError, match=r"closure 'closure' is body-based"):
        Mechanism.from_xml_string(xml)


def test_mjcf_without_closures_but_passive_joints():
    """No closure is fine for a serial chain, not for passive joints nothing determines."""
    xml = _edit(_slider(), '<weld name="closure" site1="carriage_end" site2="plate_joint"/>', "")
    with pytest.raises(ModelError, match=r"has no closure equation.*undetermined"):
        Mechanism.from_xml_string(xml)


def test_hexapod_with_a_body_based_weld():
    xml = _edit(
        HEXAPOD_XML.read_text(),
        'site1="leg3_end" site2="platform_P3"',
        'body1="leg3_end" body2="platform"',
    )
    with pytest.raises(ModelError, match=r"'leg3_closure' is body-based"):
        Mechanism.from_xml_string(xml)


def test_mjcf_file_that_does_not_exist(tmp_path):
    with pytest.raises(ModelError, match=r"MJCF file not found: .*missing.xml"):
        Mechanism.from_xml(tmp_path / "missing.xml")


def test_mjcf_that_does_not_compile(tmp_path):
    with pytest.raises(ModelError, match=r"could not compile the MJCF string"):
        Mechanism.from_xml_string("<mujoco><worldbody><body></mujoco>")
    broken = tmp_path / "broken.xml"
    broken.write_text(_edit(_slider(), 'type="slide"', 'type="telescope"'))
    with pytest.raises(ModelError, match=r"could not compile .*broken.xml"):
        Mechanism.from_xml(broken)


def test_mjcf_with_malformed_workspace():
    xml = SLIDER.replace("WORKSPACE_MIN", "-1 -1 -1")
    with pytest.raises(ModelError, match=r"'workspace_min'> must hold 6 values, has 3"):
        Mechanism.from_xml_string(xml)
