"""Another machine than the two of the papers: a 6-UPS Stewart platform closed by spherical
(site-based connect) joints, built here from scratch, goes through the same pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations
from twin.kinematics.batch import forward_batch
from twin.kinematics.single_pose import forward, inverse
from twin.mechanism import Mechanism
from twin.parameters import Parameter, ParameterSet
from twin.workspace import random_poses


def _frame_quat(z: np.ndarray) -> str:
    """wxyz quaternion of a frame whose z axis is ``z``."""
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross([1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    r = np.stack([x, np.cross(z, x), z], axis=1)
    w = np.sqrt(1.0 + np.trace(r)) / 2.0
    q = [
        w,
        (r[2, 1] - r[1, 2]) / (4 * w),
        (r[0, 2] - r[2, 0]) / (4 * w),
        (r[1, 0] - r[0, 1]) / (4 * w),
    ]
    return " ".join(f"{v:.12g}" for v in q)


def stewart_xml() -> str:
    base_r, plat_r, h = 0.30, 0.20, 0.45
    ang_b = np.radians([0, 60, 120, 180, 240, 300]) + np.radians([-10, 10] * 3)
    ang_p = np.radians([0, 60, 120, 180, 240, 300]) + np.radians([-30, 30] * 3)
    legs, welds, acts, key = [], [], [], []
    for i in range(6):
        b = np.array([base_r * np.cos(ang_b[i]), base_r * np.sin(ang_b[i]), 0.0])
        p = np.array([plat_r * np.cos(ang_p[i]), plat_r * np.sin(ang_p[i]), h])
        d = p - b
        length = float(np.linalg.norm(d))
        legs.append(f"""
    <body name="leg{i}" pos="{b[0]:.12g} {b[1]:.12g} 0" quat="{_frame_quat(d)}">
      <joint name="leg{i}_u1" type="hinge" axis="1 0 0"/>
      <joint name="leg{i}_u2" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.2" size="0.01"/>
      <body name="leg{i}_rod" pos="0 0 {length:.12g}">
        <joint name="leg{i}_p" type="slide" axis="0 0 1" ref="{length:.12g}" range="0.3 0.7"/>
        <geom type="capsule" fromto="0 0 -0.2 0 0 0" size="0.006"/>
        <site name="leg{i}_tip"/>
      </body>
    </body>""")
        welds.append(f'<connect site1="leg{i}_tip" site2="plat{i}"/>')
        acts.append(f'<position name="L{i}" joint="leg{i}_p" kp="1e5" ctrlrange="0.3 0.7"/>')
        key += [0, 0, length]
    plat_sites = "\n".join(
        f'<site name="plat{i}" pos="{plat_r * np.cos(a):.12g} {plat_r * np.sin(a):.12g} 0"/>'
        for i, a in enumerate(ang_p)
    )
    key += [0, 0, h, 1, 0, 0, 0]
    return f"""<mujoco model="stewart">
  <option><flag contact="disable"/></option>
  <custom>
    <numeric name="workspace_min" data="-0.04 -0.04 0.41 -0.1 -0.1 -0.15"/>
    <numeric name="workspace_max" data="0.04 0.04 0.49 0.1 0.1 0.15"/>
  </custom>
  <worldbody>{"".join(legs)}
    <body name="platform" pos="0 0 {h}">
      <freejoint/>
      <geom type="cylinder" size="0.22 0.01"/>
      <site name="tool"/>
      {plat_sites}
      <site name="target_a" pos="0.15 0 0.03"/>
      <site name="target_b" pos="-0.075 0.13 0.03"/>
      <site name="target_c" pos="-0.075 -0.13 0.03"/>
    </body>
  </worldbody>
  <equality>{"".join(welds)}</equality>
  <actuator>{"".join(acts)}</actuator>
  <keyframe><key name="home" qpos="{" ".join(f"{v:.12g}" for v in key)}"/></keyframe>
</mujoco>"""


@pytest.fixture(scope="module")
def stewart() -> Mechanism:
    return Mechanism.from_xml_string(stewart_xml())


def test_stewart_kinematics(stewart):
    assert [c.kind for c in stewart.closures] == ["connect"] * 6
    assert stewart.n_closure == 18 and len(stewart.free_dofs()) == 18
    poses, commands = random_poses(stewart, 10, np.random.default_rng(0))
    batch = forward_batch(stewart, commands)
    for pose, c, t in zip(poses, commands, batch.targets, strict=True):
        sol = forward(stewart, c)
        assert sol.residual < 1e-12
        np.testing.assert_allclose(sol.tool_position, pose[:3], atol=1e-11)
        np.testing.assert_allclose(t, sol.targets, atol=1e-12)
        np.testing.assert_allclose(inverse(stewart, pose).actuators, c, atol=1e-11)


def test_stewart_calibration_recovers_joint_positions_and_lengths(stewart):
    params = []
    for i in range(6):
        for k, ax in enumerate(((1, 0, 0), (0, 1, 0), (0, 0, 1))):
            params.append(Parameter(f"leg{i}.base.{'xyz'[k]}", "body_pos", f"leg{i}", ax))
            params.append(Parameter(f"leg{i}.top.{'xyz'[k]}", "site_pos", f"plat{i}", ax))
        params.append(Parameter(f"leg{i}.length", "joint_zero", f"leg{i}_p"))
    pset = ParameterSet(params, stewart.model)
    rng = np.random.default_rng(1)
    truth_values = rng.uniform(-1e-3, 1e-3, len(pset))
    truth = Mechanism(pset.inject(stewart.model, truth_values))
    _, commands = random_poses(stewart, 20, rng)
    measured = forward_batch(truth, commands).targets
    model = CalibrationModel(stewart, pset)
    res = identify(model, Observations(commands, measured))
    # targets measured in the base frame fix every joint position: all 42 are identifiable
    assert res.report.n_identifiable == 42
    assert np.max(np.abs(res.values - truth_values)) < 1e-12  # metres
    assert res.residual_rms < 1e-12
