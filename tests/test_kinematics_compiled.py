"""The compiled kernels of batched forward kinematics (twin.kinematics.compiled*).

* their kinematic tree equals MuJoCo's ``mj_kinematics`` for every joint kind (hinge with
  general and negative axes, slide, ball, free), joint offsets and turned sites;
* their forward kinematics equals the numpy path to round-off on the three machines, and the
  single-pose MuJoCo Newton solve on a weld held by a free body (square) and a weld held by a
  ball joint (more equations than unknowns: Householder least squares);
* thread count changes no bit; a pose that cannot close raises ClosureError naming it, as the
  numpy path does.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from test_kinematics_fast import MACHINES, machines_with_commands

from twin.exceptions import ClosureError
from twin.kinematics.batch import forward_batch
from twin.kinematics.compiled import compiled_plan, model_numbers
from twin.kinematics.kernels import site_frame, tree
from twin.kinematics.single_pose import forward
from twin.kinematics.structure import fast_kinematics
from twin.mechanism import Mechanism


def _every_joint_model() -> mujoco.MjModel:
    from test_kinematics_fast import EVERY_JOINT

    return mujoco.MjModel.from_xml_string(EVERY_JOINT)


def test_compiled_tree_equals_mujoco_for_every_joint_kind():
    from test_kinematics_fast import _mujoco_frames, _random_configurations

    model = _every_joint_model()
    assert set(model.jnt_type.tolist()) == {0, 1, 2, 3}  # free, ball, slide, hinge
    num = model_numbers(model)
    site_pos, site_rot, turned = num[-3:]
    assert turned.any() and not turned.all()
    assert set(num[7].tolist()) == {0, 1, 2, 3}  # general, +x and -z hinges (the free: 0)
    assert num[2].any() and not num[2].all() and num[4].any() and not num[4].all()
    ints = lambda x: np.ascontiguousarray(x, dtype=np.int64)  # noqa: E731
    xpos, xmat = np.empty((model.nbody, 3)), np.empty((model.nbody, 3, 3))
    xanchor, xaxis = np.empty((model.njnt, 3)), np.empty((model.njnt, 3))
    qs = _random_configurations(model, 12, 5)
    for q, ref in zip(qs, _mujoco_frames(model, qs), strict=True):
        tree(
            q, ints(model.body_parentid), ints(model.body_jntadr), ints(model.body_jntnum),
            ints(model.jnt_type), ints(model.jnt_qposadr), *num[:10], xpos, xmat, xanchor,
            xaxis, np.empty((3, 3)),
        )  # fmt: skip
        np.testing.assert_allclose(xpos, ref["xpos"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(xmat.reshape(-1, 9), ref["xmat"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(xanchor, ref["xanchor"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(xaxis, ref["xaxis"], rtol=0, atol=1e-12)
        pos, rot = np.empty(3), np.empty((3, 3))
        for s in range(model.nsite):
            site_frame(s, ints(model.site_bodyid), site_pos, site_rot, turned, xpos, xmat, pos, rot)
            np.testing.assert_allclose(pos, ref["site_xpos"][s], rtol=0, atol=1e-12)
            np.testing.assert_allclose(rot.reshape(9), ref["site_xmat"][s], rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def machines():
    return machines_with_commands(300, 7)


@pytest.mark.parametrize("name", MACHINES)
def test_compiled_equals_numpy_path(machines, name):
    mech, commands = machines[name]
    assert compiled_plan(fast_kinematics(mech)) is not None  # the kernels cover the machine
    fast = forward_batch(mech, commands)
    ref = forward_batch(mech, commands, compiled=False)
    np.testing.assert_allclose(fast.targets, ref.targets, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.tool_position, ref.tool_position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.tool_rotation, ref.tool_rotation, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.qpos, ref.qpos, rtol=0, atol=1e-10)
    # both converged (the same Newton; how many steps each took near the tolerance is the
    # round-off's to decide, not asserted)
    assert np.all(fast.residual < 1e-12) and np.all(ref.residual < 1e-12)
    # warm starts (the identification's repeated solves) as well
    warm = forward_batch(mech, commands, start=ref.qpos)
    np.testing.assert_allclose(warm.targets, ref.targets, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher"])
def test_thread_count_changes_no_bit(machines, name):
    mech, commands = machines[name]
    one = forward_batch(mech, commands, nthread=1)
    two = forward_batch(mech, commands, nthread=2)
    three = forward_batch(mech, commands, nthread=3)
    for other in (two, three):
        assert np.array_equal(one.targets, other.targets)
        assert np.array_equal(one.qpos, other.qpos)


# a crank turning a body that a weld ties to it: held by a free joint (6 unknowns, 6
# equations: square) or by a ball joint at the crank's axis (3 unknowns, 6 consistent
# equations: least squares)
HELD = """
<mujoco>
  <worldbody>
    <body name="crank">
      <joint name="j1" type="hinge" axis="0.2 0.1 1" range="-60 60"/>
      <site name="tip" pos="0.3 0.1 0.05" quat="0.9 0.2 0.3 0.1"/>
      <site name="tool" pos="0.2 0 0"/>
    </body>
    <body name="held" pos="0.25 0.05 0.1" quat="0.8 0.1 0.5 0.2">
      {joint}
      <site name="end" pos="{end}" quat="{quat}"/>
      <site name="target_1" pos="0.1 0.2 0.3"/>
      <site name="target_2" pos="-0.1 0.05 0.2"/>
    </body>
  </worldbody>
  <equality><weld site1="end" site2="tip"/></equality>
  <actuator><position name="crank" joint="j1"/></actuator>
  <keyframe><key name="home" qpos="{home}"/></keyframe>
</mujoco>
"""


def _held_by(kind: str) -> Mechanism:
    if kind == "free":
        joint, end, quat = '<freejoint name="f"/>', "0.05 0.02 0", "0.9 0.1 0.2 0.3"
        home = "0 0.25 0.05 0.1 0.8 0.1 0.5 0.2"
    else:  # the ball at the crank's axis: the weld's position rows hold for any rotation
        joint, end, quat = '<joint name="b" type="ball" pos="0 0 0"/>', "0 0 0", "0.9 0.1 0.2 0.3"
        home = "0 0.8 0.1 0.5 0.2"
    xml = HELD.format(joint=joint, end=end, quat=quat, home=home)
    if kind == "ball":  # the crank's tip on the ball's centre, the ball's body at the origin
        xml = xml.replace('name="tip" pos="0.3 0.1 0.05"', 'name="tip" pos="0 0 0"')
        xml = xml.replace('name="held" pos="0.25 0.05 0.1" quat="0.8 0.1 0.5 0.2"', 'name="held"')
        xml = xml.replace('qpos="0 0.8 0.1 0.5 0.2"', 'qpos="0 1 0 0 0"')
    return Mechanism.from_xml_string(xml)


@pytest.mark.parametrize("kind", ["free", "ball"])
def test_compiled_equals_single_pose_solve_on_free_and_ball_joints(kind):
    mech = _held_by(kind)
    cs = fast_kinematics(mech).closure
    assert cs.square == (kind == "free")
    assert compiled_plan(fast_kinematics(mech)) is not None
    commands = np.linspace(-0.9, 0.9, 40)[:, None]
    batch = forward_batch(mech, commands)
    assert np.all(batch.residual < 1e-12)
    for k, c in enumerate(commands):
        single = forward(mech, c)
        np.testing.assert_allclose(batch.targets[k], single.targets, rtol=0, atol=1e-9)
        np.testing.assert_allclose(batch.tool_rotation[k], single.tool_rotation, atol=1e-9)
    ref = forward_batch(mech, commands, compiled=False)
    np.testing.assert_allclose(batch.targets, ref.targets, rtol=0, atol=1e-12)


def test_a_pose_that_cannot_close_is_named(machines):
    mech, commands = machines["hexapod_rrrprr"]
    bad = commands[:50].copy()
    bad[17, 0] = mech.actuator_range[0, 1] * 50.0  # one limb far longer than the others reach
    messages = []
    for compiled in (True, False):
        with pytest.raises(ClosureError) as err:
            forward_batch(mech, bad, compiled=compiled, check_stroke=False)
        messages.append(str(err.value))
    assert "pose 17" in messages[0] and "1 of 50" in messages[0]
    assert messages[0].split("residual")[0] == messages[1].split("residual")[0]


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher"])
def test_second_order_predictor_starts_closer_and_changes_no_solution(machines, name, monkeypatch):
    import twin.kinematics.batch as kb
    import twin.kinematics.structure as kf

    mech, commands = machines[name]
    fk = fast_kinematics(mech)
    home = mech.home_qpos
    # difference_soa inverts integrate_soa (simple, ball and free joints)
    step = np.random.default_rng(9).normal(0.0, 0.05, (len(mech.free_dofs()), 20))
    q = np.repeat(home[:, None], 20, axis=1)
    moved = q.copy()
    kf.integrate_soa(fk, moved, step)
    np.testing.assert_allclose(kf.difference_soa(fk, q, moved), step, rtol=0, atol=1e-12)
    # the start of each order against the closed solutions
    exact = forward_batch(mech, commands, start=home)
    starts = {}
    for order, minimum in (("first", 10**9), ("second", 1)):
        monkeypatch.setattr(kb, "CURVATURE_MIN", minimum)
        q0 = np.repeat(home[:, None], len(commands), axis=1)
        kb.predict_start(fk, q0, commands)
        starts[order] = np.abs(kf.difference_soa(fk, q0, exact.qpos.T)).max(axis=0)
        sol = forward_batch(mech, commands)
        np.testing.assert_allclose(sol.targets, exact.targets, rtol=0, atol=1e-12)
    assert np.median(starts["second"]) < 0.5 * np.median(starts["first"])
