"""A serial arm is a mechanism with zero closure equations, through the same code path.

A 3R arm with no inertia anywhere in its MJCF (kinematics only): it compiles with defaulted
masses (and says so), forward kinematics is direct and agrees with a plain product of
rotations and translations, the identification Jacobian (no implicit-function part) agrees
with finite differences, and noise-free readings give its errors back exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations
from twin.exceptions import ModelError
from twin.kinematics.batch import forward_batch
from twin.kinematics.sensitivity import target_jacobian
from twin.kinematics.single_pose import forward, inverse
from twin.mechanism import Mechanism
from twin.parameters import Parameter, ParameterSet
from twin.rotations import rpy_from_matrix

L1, L2, L3 = 0.35, 0.30, 0.12

ARM = f"""<mujoco model="arm3r">
  <compiler angle="radian"/>
  <worldbody>
    <body name="link1" pos="0 0 0.4">
      <joint name="j1" type="hinge" axis="0 0 1" range="-3 3"/>
      <body name="link2" pos="0 0 0.05">
        <joint name="j2" type="hinge" axis="0 1 0" range="-2 2"/>
        <body name="link3" pos="{L1} 0 0">
          <joint name="j3" type="hinge" axis="0 1 0" range="-2.5 2.5"/>
          <site name="tool" pos="{L2} 0 0"/>
          <site name="target_1" pos="{L2 + 0.02} 0.03 {L3}"/>
          <site name="target_2" pos="{L2} -0.04 0.02"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="j1" joint="j1"/><motor name="j2" joint="j2"/><motor name="j3" joint="j3"/>
  </actuator>
  <keyframe><key name="home" qpos="0 0.3 -0.6"/></keyframe>
</mujoco>"""


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _by_hand(q: np.ndarray, site: np.ndarray) -> np.ndarray:
    """The arm's chain as a product of rotations and translations, written out."""
    r1 = _rz(q[0])
    p2 = np.array([0, 0, 0.4]) + r1 @ np.array([0, 0, 0.05])
    r2 = r1 @ _ry(q[1])
    p3 = p2 + r2 @ np.array([L1, 0, 0])
    r3 = r2 @ _ry(q[2])
    return p3 + r3 @ site


@pytest.fixture(scope="module")
def arm() -> Mechanism:
    return Mechanism.from_xml_string(ARM)


@pytest.fixture(scope="module")
def params(arm) -> ParameterSet:
    entries = [
        Parameter("link2.dx", "body_pos", "link2", (1, 0, 0)),
        Parameter("link2.dz", "body_pos", "link2", (0, 0, 1)),
        Parameter("link3.dx", "body_pos", "link3", (1, 0, 0)),
        Parameter("link3.dy", "body_pos", "link3", (0, 1, 0)),
        Parameter("link3.rx", "body_rot", "link3", (1, 0, 0)),
        Parameter("link3.rz", "body_rot", "link3", (0, 0, 1)),
        Parameter("j2.zero", "joint_zero", "j2"),
        Parameter("j3.zero", "joint_zero", "j3"),
        Parameter("target_1.dy", "site_pos", "target_1", (0, 1, 0)),
    ]
    return ParameterSet(entries, arm.model)


def _commands(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform([-2.5, -1.5, -2.0], [2.5, 1.5, 2.0], (n, 3))


def test_a_serial_chain_without_masses_loads_and_says_so(arm):
    assert arm.is_serial and arm.n_closure == 0 and arm.free_dofs().size == 0
    assert arm.masses_defaulted
    assert arm.with_model(arm.model).masses_defaulted


def test_a_passive_joint_without_closure_is_refused():
    xml = ARM.replace('<motor name="j3" joint="j3"/>', "")
    with pytest.raises(ModelError, match=r"no closure.*\['j3'\].*undetermined"):
        Mechanism.from_xml_string(xml)


def test_forward_kinematics_is_direct_and_matches_the_chain_by_hand(arm):
    commands = _commands(20, 0)
    batch = forward_batch(arm, commands)
    local = arm.model.site_pos[arm.target_sites]
    for c, targets, tool in zip(commands, batch.targets, batch.tool_position, strict=True):
        sol = forward(arm, c)
        assert sol.iterations == 0 and sol.residual == 0.0
        np.testing.assert_allclose(sol.targets, targets, atol=1e-15)
        np.testing.assert_allclose(tool, _by_hand(c, np.array([L2, 0, 0])), atol=1e-14)
        for t, p in zip(targets, local, strict=True):
            np.testing.assert_allclose(t, _by_hand(c, p), atol=1e-14)


def test_inverse_then_forward_round_trip(arm):
    for c in _commands(5, 1):
        pose_sol = forward(arm, c)
        pose = np.concatenate([pose_sol.tool_position, rpy_from_matrix(pose_sol.tool_rotation)])
        back = inverse(arm, pose, start=np.concatenate([c[:1], c[1:] + 0.05]))
        np.testing.assert_allclose(back.tool_position, pose_sol.tool_position, atol=1e-12)


def test_identification_jacobian_against_finite_differences(arm, params):
    x = np.random.default_rng(2).uniform(-1e-3, 1e-3, len(params))
    mech = arm.with_model(params.inject(arm.model, x))
    c = _commands(1, 3)[0]
    jac = target_jacobian(mech, params, x, forward(mech, c).qpos)
    h = 1e-7
    fd = np.zeros_like(jac)
    for k in range(len(params)):
        for sign in (1, -1):
            xk = x.copy()
            xk[k] += sign * h
            t = forward(arm.with_model(params.inject(arm.model, xk)), c).targets.reshape(-1)
            fd[:, k] += sign * t / (2 * h)
    np.testing.assert_allclose(jac, fd, atol=1e-8)


def test_noise_free_recovery(arm, params):
    rng = np.random.default_rng(4)
    truth = rng.uniform(-1e-3, 1e-3, len(params))
    commands = _commands(15, 5)
    measured = forward_batch(arm.with_model(params.inject(arm.model, truth)), commands).targets
    res = identify(CalibrationModel(arm, params), Observations(commands, measured))
    assert res.report.n_identifiable == len(params)
    assert np.max(np.abs(res.values - truth)) < 1e-11
