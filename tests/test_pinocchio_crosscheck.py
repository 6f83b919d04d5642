"""Pinocchio cross-checks MuJoCo: site poses, closures and site Jacobians of the hexapod.

Both engines read the same MJCF; MuJoCo's closed configurations from the Newton forward
kinematics are mapped to pinocchio coordinates and every site must agree to round-off.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

import mujoco  # noqa: E402

from twin.exceptions import ModelError  # noqa: E402
from twin.kinematics.pinocchio_model import (  # noqa: E402
    frame_jacobian_world,
    frame_placement,
    pinocchio_from_mjcf,
    pinocchio_mjcf_string,
    qpos_mujoco_to_pinocchio,
    site_frame_id,
    velocity_map,
)
from twin.kinematics.single_pose import forward  # noqa: E402
from twin.mechanism import Mechanism  # noqa: E402
from twin.rotations import rotvec_from_matrix  # noqa: E402
from twin.workspace import random_poses  # noqa: E402

HEXAPOD = Path(__file__).resolve().parents[1] / "models" / "hexapod_rrrprr.xml"
N_POSES = 10
POSE_TOL = 1e-12
JAC_TOL = 1e-10


@pytest.fixture(scope="module")
def mech() -> Mechanism:
    return Mechanism.from_xml(HEXAPOD)


@pytest.fixture(scope="module")
def pin_model() -> tuple:
    return pinocchio_from_mjcf(HEXAPOD)


@pytest.fixture(scope="module")
def closed_qpos(mech: Mechanism) -> list[np.ndarray]:
    """Closed configurations from MuJoCo's forward kinematics at seeded random poses."""
    _, commands = random_poses(mech, N_POSES, np.random.default_rng(20240611))
    sols = [forward(mech, c) for c in commands]
    assert all(s.residual < 1e-12 for s in sols)
    return [s.qpos for s in sols]


def _site_names(model: mujoco.MjModel) -> list[str]:
    return [model.site(i).name for i in range(model.nsite)]


def _mujoco_sites(mech: Mechanism, qpos: np.ndarray) -> mujoco.MjData:
    d = mech.data
    d.qpos[:] = qpos
    mujoco.mj_kinematics(mech.model, d)
    mujoco.mj_comPos(mech.model, d)
    return d


# --------------------------------------------------------------------------- the model
def test_model_matches_mujoco_structure(mech: Mechanism, pin_model: tuple) -> None:
    model, _ = pin_model
    m = mech.model
    # 6 legs x (hinge + hinge/hinge composite + slide + hinge + hinge) + free flyer
    assert (model.nq, model.nv) == (m.nq, m.nv)
    assert model.njoints - 1 == 6 * 5 + 1
    for name in _site_names(m):  # every site, the world-level one included, is a frame
        site_frame_id(model, name)


def test_wrapped_file_is_for_pinocchio_only() -> None:
    xml = pinocchio_mjcf_string(HEXAPOD)
    assert "ref=" not in xml and "<keyframe" not in xml
    assert 'name="leg1_end__body"' in xml and 'site1="leg1_end"' in xml
    with pytest.raises(ValueError, match="free joint"):
        mujoco.MjModel.from_xml_string(xml)


def test_unknown_site_raises(pin_model: tuple) -> None:
    with pytest.raises(ModelError, match="no site frame 'nowhere'"):
        site_frame_id(pin_model[0], "nowhere")


def test_home_slide_coordinate_is_displacement_from_ref(mech: Mechanism, pin_model: tuple) -> None:
    model, _ = pin_model
    q = qpos_mujoco_to_pinocchio(mech.model, model, mech.home_qpos)
    slide = model.joints[model.getJointId("leg1_slide")]
    assert mech.home_qpos[mech.actuator_qpos[0]] == pytest.approx(0.230714809723)
    assert q[slide.idx_q] == 0.0  # home length = ref: no displacement
    free = model.joints[model.getJointId("platform_free")]
    np.testing.assert_array_equal(q[free.idx_q : free.idx_q + 7], [0, 0, 0.22, 0, 0, 0, 1])


# --------------------------------------------------------------------------- poses
def test_site_poses_match_mujoco(mech: Mechanism, pin_model: tuple, closed_qpos: list) -> None:
    model, _ = pin_model
    data = model.createData()
    names = _site_names(mech.model)
    for qpos in closed_qpos:
        d = _mujoco_sites(mech, qpos)
        q = qpos_mujoco_to_pinocchio(mech.model, model, qpos)
        for s, name in enumerate(names):
            r, p = frame_placement(model, data, q, name)
            np.testing.assert_allclose(p, d.site_xpos[s], rtol=0, atol=POSE_TOL, err_msg=name)
            np.testing.assert_allclose(
                r, d.site_xmat[s].reshape(3, 3), rtol=0, atol=POSE_TOL, err_msg=name
            )


def test_closures_hold_in_pinocchio(mech: Mechanism, pin_model: tuple, closed_qpos: list) -> None:
    model, _ = pin_model
    data = model.createData()
    m = mech.model
    for qpos in closed_qpos:
        q = qpos_mujoco_to_pinocchio(m, model, qpos)
        for c in mech.closures:
            ra, pa = frame_placement(model, data, q, m.site(c.site_a).name)
            rb, pb = frame_placement(model, data, q, m.site(c.site_b).name)
            assert np.max(np.abs(pa - pb)) < POSE_TOL, c.name
            assert np.max(np.abs(rotvec_from_matrix(ra @ rb.T))) < POSE_TOL, c.name


def test_closures_break_off_the_solution(
    mech: Mechanism, pin_model: tuple, closed_qpos: list
) -> None:
    """The residual check has teeth: 1 mrad on one base joint opens that leg's loop only."""
    model, _ = pin_model
    data = model.createData()
    m = mech.model
    qpos = closed_qpos[0].copy()
    qpos[m.joint("leg2_base_x").qposadr[0]] += 1e-3
    q = qpos_mujoco_to_pinocchio(m, model, qpos)
    gaps = []
    for c in mech.closures:
        _, pa = frame_placement(model, data, q, m.site(c.site_a).name)
        _, pb = frame_placement(model, data, q, m.site(c.site_b).name)
        gaps.append(np.linalg.norm(pa - pb))
    assert gaps[1] > 1e-5
    assert max(gaps[:1] + gaps[2:]) < POSE_TOL
    _, constraints = pin_model
    if constraints is not None:  # pinocchio's own weld residuals see the same single gap
        pin.forwardKinematics(model, data, q)
        errors = []
        for cm in constraints:
            cd = cm.createData()
            cm.calc(model, data, cd)
            errors.append(np.max(np.abs(cd.constraint_position_error)))
        assert sorted(errors)[-1] > 1e-5
        assert sorted(errors)[-2] < POSE_TOL


# --------------------------------------------------------------------------- Jacobians
def test_site_jacobians_match_mujoco(mech: Mechanism, pin_model: tuple, closed_qpos: list) -> None:
    model, _ = pin_model
    data = model.createData()
    m = mech.model
    jp = np.zeros((3, m.nv))
    jr = np.zeros((3, m.nv))
    for qpos in closed_qpos:
        d = _mujoco_sites(mech, qpos)
        q = qpos_mujoco_to_pinocchio(m, model, qpos)
        t = velocity_map(m, model, qpos)
        for s, name in enumerate(_site_names(m)):
            mujoco.mj_jacSite(m, d, jp, jr, s)
            jac = frame_jacobian_world(model, data, q, name) @ t
            np.testing.assert_allclose(jac[:3], jp, rtol=0, atol=JAC_TOL, err_msg=name)
            np.testing.assert_allclose(jac[3:], jr, rtol=0, atol=JAC_TOL, err_msg=name)


def test_velocity_map_is_identity_on_legs_and_rotates_platform_linear_part(
    mech: Mechanism, pin_model: tuple, closed_qpos: list
) -> None:
    model, _ = pin_model
    m = mech.model
    qpos = closed_qpos[0]
    t = velocity_map(m, model, qpos)
    free = m.joint("platform_free")
    a = free.dofadr[0]
    legs = np.r_[0:a, a + 6 : m.nv]
    np.testing.assert_array_equal(t[np.ix_(legs, legs)], np.eye(len(legs)))
    np.testing.assert_array_equal(t[a + 3 : a + 6, a + 3 : a + 6], np.eye(3))
    _mujoco_sites(mech, qpos)
    r = mech.data.xmat[m.body("platform").id].reshape(3, 3)
    np.testing.assert_allclose(t[a : a + 3, a : a + 3], r.T, rtol=0, atol=1e-15)
    assert not np.allclose(r, np.eye(3), atol=1e-3)  # a tilted platform: the map matters


def test_jacobian_matches_finite_difference_of_pinocchio(
    mech: Mechanism, pin_model: tuple, closed_qpos: list
) -> None:
    """Pinocchio's own Jacobian is its pose derivative (one site, central differences)."""
    model, _ = pin_model
    data = model.createData()
    q = qpos_mujoco_to_pinocchio(mech.model, model, closed_qpos[0])
    jac = frame_jacobian_world(model, data, q, "target_2")
    r0, _ = frame_placement(model, data, q, "target_2")
    h = 1e-6
    fd = np.zeros_like(jac)
    for k in range(model.nv):
        dv = np.zeros(model.nv)
        dv[k] = h
        rp, pp = frame_placement(model, data, pin.integrate(model, q, dv), "target_2")
        rm, pm = frame_placement(model, data, pin.integrate(model, q, -dv), "target_2")
        fd[:3, k] = (pp - pm) / (2 * h)
        fd[3:, k] = (rotvec_from_matrix(rp @ r0.T) - rotvec_from_matrix(rm @ r0.T)) / (2 * h)
    np.testing.assert_allclose(jac, fd, rtol=0, atol=1e-8)


# --------------------------------------------------------------------------- constraints
def test_constraints_are_the_six_welds(
    mech: Mechanism, pin_model: tuple, closed_qpos: list
) -> None:
    model, constraints = pin_model
    if constraints is None:
        pytest.skip("this pinocchio cannot import MJCF constraints")
    assert len(constraints) == 6
    assert all(c.shortname() == "FrameAnchorConstraintModel" for c in constraints)
    m = mech.model
    # pair each constraint with its weld: the leg-end site (site1) moves with joint1
    by_joint = {
        model.frames[site_frame_id(model, m.site(c.site_a).name)].parentJoint: c
        for c in mech.closures
    }
    pairs = [(cm, by_joint[cm.joint1_id]) for cm in constraints]
    assert len({id(c) for _, c in pairs}) == 6
    data = model.createData()
    for qpos in closed_qpos:
        q = qpos_mujoco_to_pinocchio(m, model, qpos)
        pin.framesForwardKinematics(model, data, q)
        d = _mujoco_sites(mech, qpos)
        for cm, closure in pairs:
            cd = cm.createData()
            cm.calc(model, data, cd)
            assert np.max(np.abs(cd.constraint_position_error)) < POSE_TOL
            # the anchors are the weld's sites: leg end (site1) and platform joint (site2)
            for placement, site in ((cd.oMc1, closure.site_a), (cd.oMc2, closure.site_b)):
                np.testing.assert_allclose(
                    placement.translation, d.site_xpos[site], rtol=0, atol=POSE_TOL
                )
                np.testing.assert_allclose(
                    placement.rotation, d.site_xmat[site].reshape(3, 3), rtol=0, atol=POSE_TOL
                )


# --------------------------------------------------------------------------- ref and quaternions
SMALL = """
<mujoco model="ref_check">
  <compiler angle="degree"/>
  <worldbody>
    <site name="world_mark" pos="0.1 0 0" euler="0 0 30"/>
    <body name="arm" pos="0.1 0.2 0.3" quat="0.9 0.1 0.2 0.3">
      <joint name="a_hinge" type="hinge" axis="0 1 1" ref="40" pos="0.05 0 0"/>
      <joint name="a_slide" type="slide" axis="1 1 0" ref="0.02"/>
      <geom size="0.05"/>
      <body name="fore" pos="0 0 0.4">
        <joint name="f_hinge" type="hinge" axis="1 0 0" ref="-25" pos="0 0.03 0"/>
        <geom size="0.05"/>
        <body name="wrist" pos="0.1 0 0">
          <joint name="w_ball" type="ball" pos="0.01 0.02 0"/>
          <geom size="0.05"/>
          <site name="wrist" pos="0.1 0.2 0.3" quat="0.5 0.5 0.1 0"/>
        </body>
      </body>
    </body>
    <body name="float" pos="0 0 1">
      <freejoint name="float_free"/>
      <geom size="0.05"/>
      <body name="float_tip" pos="0.2 0 0">
        <joint name="t_slide" type="slide" axis="0 0 1" ref="0.1"/>
        <geom size="0.05"/>
        <site name="tip" pos="0 0.1 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_ref_quaternions_and_free_velocity_on_a_small_model(tmp_path: Path) -> None:
    """Hinge and slide ``ref`` (solo and in a multi-joint body), ball and free quaternions."""
    path = tmp_path / "ref_check.xml"
    path.write_text(SMALL)
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    model, _ = pinocchio_from_mjcf(path, constraints=False)
    data = model.createData()
    assert (model.nq, model.nv) == (m.nq, m.nv)
    rng = np.random.default_rng(7)
    jp = np.zeros((3, m.nv))
    jr = np.zeros((3, m.nv))
    for _ in range(5):
        qpos = m.qpos0.copy()
        dq = rng.normal(scale=0.5, size=m.nv)
        mujoco.mj_integratePos(m, qpos, dq, 1.0)
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        q = qpos_mujoco_to_pinocchio(m, model, qpos)
        t = velocity_map(m, model, qpos)
        for s, name in enumerate(_site_names(m)):
            r, p = frame_placement(model, data, q, name)
            np.testing.assert_allclose(p, d.site_xpos[s], rtol=0, atol=POSE_TOL, err_msg=name)
            np.testing.assert_allclose(r, d.site_xmat[s].reshape(3, 3), rtol=0, atol=POSE_TOL)
            mujoco.mj_jacSite(m, d, jp, jr, s)
            jac = frame_jacobian_world(model, data, q, name) @ t
            np.testing.assert_allclose(jac, np.vstack([jp, jr]), rtol=0, atol=JAC_TOL)
