"""The committed hexapod MJCF: generator sync, Table 1 geometry, counts, Table 3 limits."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from twin.kinematics.single_pose import inverse

ROOT = Path(__file__).resolve().parent.parent
HEXAPOD_XML = ROOT / "models" / "hexapod_rrrprr.xml"
HEXAPOD_PARAMS = ROOT / "models" / "hexapod_rrrprr.params.toml"

LEGS = range(1, 7)

# Han et al. 2019, Table 1 (mm): base joints B_i and platform joints P_i. Table 1 prints
# Y_P2 as "5.9" (an extraction error); the 120-degree symmetry gives 115.911.
X_B = (173.867, -46.587, -127.279, -127.279, -46.587, 173.867)
Y_B = (46.587, 173.867, 127.279, -127.279, -173.867, -46.587)
X_P = (84.853, 31.058, -115.911, -115.911, 31.058, 84.853)
Y_P = (84.853, 115.911, 31.058, -31.058, -115.911, -84.853)
L_B = L_P = 5.0  # mm, Han et al. 2019, Table 1
HOME_LIMB = 230.715  # mm, Han et al. 2019, Table 1 (L_i at the home pose)
HOME_POSE = np.array([0.0, 0.0, 0.220, 0.0, 0.0, 0.0])


# ----------------------------------------------------------------------------- Table 1
@pytest.mark.parametrize("leg", LEGS)
def test_base_joint_positions_match_table1(hexapod, leg):
    # Han et al. 2019, Table 1: B_i in the base frame, z = 0.
    pos_mm = hexapod.model.body(f"leg{leg}_base").pos * 1e3
    np.testing.assert_allclose(pos_mm, [X_B[leg - 1], Y_B[leg - 1], 0.0], rtol=0, atol=1e-3)
    assert hexapod.model.body(f"leg{leg}_base").parentid[0] == 0  # expressed in the base frame


@pytest.mark.parametrize("leg", LEGS)
def test_platform_joint_positions_match_table1(hexapod, leg):
    # Han et al. 2019, Table 1: P_i in the platform frame O_P, z = 0.
    m = hexapod.model
    site = m.site(f"platform_P{leg}")
    assert m.body(int(site.bodyid[0])).name == "platform"
    np.testing.assert_allclose(site.pos * 1e3, [X_P[leg - 1], Y_P[leg - 1], 0.0], rtol=0, atol=1e-3)


@pytest.mark.parametrize("leg", LEGS)
def test_joint_offsets_match_table1(hexapod, leg):
    # Han et al. 2019, Table 1: L_B = L_P = 5 mm, the arms of the offset RR joints.
    m = hexapod.model
    np.testing.assert_allclose(m.body(f"leg{leg}_lower").pos * 1e3, [0, 0, L_B], atol=1e-12)
    np.testing.assert_allclose(m.body(f"leg{leg}_end").pos * 1e3, [0, 0, L_P], atol=1e-12)


def test_base_and_platform_circles(hexapod):
    """The Table 1 points lie on 180 mm and 120 mm circles at the paper's angles."""
    m = hexapod.model
    base = np.array([m.body(f"leg{i}_base").pos for i in LEGS])
    plat = np.array([m.site(f"platform_P{i}").pos for i in LEGS])
    np.testing.assert_allclose(np.linalg.norm(base, axis=1), 0.180, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(plat, axis=1), 0.120, atol=1e-12)
    angles_b = np.degrees(np.arctan2(base[:, 1], base[:, 0])) % 360
    angles_p = np.degrees(np.arctan2(plat[:, 1], plat[:, 0])) % 360
    np.testing.assert_allclose(angles_b, [15, 105, 135, 225, 255, 345], atol=1e-9)
    np.testing.assert_allclose(angles_p, [45, 75, 165, 195, 285, 315], atol=1e-9)


def test_home_limb_lengths_match_table1(hexapod):
    # Han et al. 2019, Table 1: all six limbs measure 230.715 mm at the home pose.
    sol = inverse(hexapod, HOME_POSE)
    assert sol.actuators.shape == (6,)
    np.testing.assert_allclose(sol.actuators * 1e3, HOME_LIMB, rtol=0, atol=1e-3)
    # the home keyframe is that very configuration
    np.testing.assert_allclose(sol.qpos, hexapod.home_qpos, atol=1e-11)


# ----------------------------------------------------------------------------- counts
def test_model_counts(hexapod):
    m = hexapod.model
    assert hexapod.actuator_names == ("leg1", "leg2", "leg3", "leg4", "leg5", "leg6")
    assert all(hexapod.actuator_is_slide)
    assert [m.joint(int(j)).name for j in hexapod.actuator_joints] == [
        f"leg{i}_slide" for i in LEGS
    ]
    assert len(hexapod.closures) == 6
    assert [c.kind for c in hexapod.closures] == ["weld"] * 6
    assert [c.name for c in hexapod.closures] == [f"leg{i}_closure" for i in LEGS]
    assert hexapod.target_names == ("target_1", "target_2", "target_3")
    assert hexapod.n_targets == 3
    assert m.nv == 42 and m.nq == 43
    assert hexapod.n_closure == 36
    # exactly determined: closure rows = free dofs once the actuators are held
    assert len(hexapod.free_dofs()) == hexapod.n_closure
    assert m.body(int(hexapod.tool_body)).name == "platform"


# ----------------------------------------------------------------------------- Table 3
def test_stroke_matches_table3(hexapod):
    # Han et al. 2019, Table 3: limb stroke 195-265 mm.
    np.testing.assert_allclose(hexapod.actuator_range * 1e3, [[195.0, 265.0]] * 6, atol=1e-12)


def test_workspace_matches_table3(hexapod):
    # Han et al. 2019, Table 3: +-25 mm in x, y; 200-240 mm in z; +-15, +-15, +-20 deg.
    lo, hi = hexapod.workspace_min, hexapod.workspace_max
    assert lo is not None and hi is not None
    np.testing.assert_allclose(lo[:3] * 1e3, [-25.0, -25.0, 200.0], atol=1e-9)
    np.testing.assert_allclose(hi[:3] * 1e3, [25.0, 25.0, 240.0], atol=1e-9)
    np.testing.assert_allclose(np.degrees(lo[3:]), [-15.0, -15.0, -20.0], atol=1e-9)
    np.testing.assert_allclose(np.degrees(hi[3:]), [15.0, 15.0, 20.0], atol=1e-9)


# ----------------------------------------------------------------------------- MuJoCo itself
def test_mujoco_opens_the_file_and_welds_hold_at_home():
    m = mujoco.MjModel.from_xml_path(str(HEXAPOD_XML))
    d = mujoco.MjData(m)
    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home")
    assert key >= 0
    mujoco.mj_resetDataKeyframe(m, d, key)
    mujoco.mj_forward(m, d)
    eq_rows = d.efc_type[: d.nefc] == int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)
    assert int(eq_rows.sum()) == 36  # 6 welds x 6 rows
    assert np.max(np.abs(d.efc_pos[: d.nefc][eq_rows])) < 1e-9
