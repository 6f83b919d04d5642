"""Writes models/hexapod_rrrprr.xml from the second paper's Table 1 (run: python models/build_hexapod.py).

The XML is the single source of truth for the shape; this script only documents how
its numbers were derived, and a test checks that the committed XML equals its output.

Geometry (Han et al. 2019, Table 1 and section "Structural modeling"):
* base joints B_i on a 180 mm circle at 15, 105, 135, 225, 255, 345 deg (z = 0);
* platform joints P_i on a 120 mm circle at 45, 75, 165, 195, 285, 315 deg (z = 0 in the
  platform frame). Table 1 prints Y_P2 as "5.9" (an extraction error): the 120-degree
  symmetry of the other entries gives 120 sin 75 deg = 115.911 mm, which is used;
* offset RR joints: at B_i the first revolute axis is the radial axis X_Bi (O_B -> B_i); an
  arm of L_B = 5 mm, perpendicular to that axis, runs to D_i; the second revolute axis at D_i
  is perpendicular to the first axis and the arm, so the limb stays in the plane of X_Bi and
  the arm; then a roll joint about the limb, the actuated prismatic joint D_i -> C_i, and the
  same offset RR joint mirrored at the platform (axes X_Pi, arm L_P = 5 mm from C_i to P_i);
* the home pose is z = 220 mm, no rotation; there the six limbs measure 230.715 mm (Table 1).

Frames are chosen so that every joint reads zero at home except the prismatic joints,
which read the limb length |D_i C_i| (their ``ref`` is the home length).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from twin.formats.mjcf_numbers import canonical_quat, fmt

BASE_RADIUS = 0.180
PLATFORM_RADIUS = 0.120
BASE_ANGLES_DEG = (15.0, 105.0, 135.0, 225.0, 255.0, 345.0)
PLATFORM_ANGLES_DEG = (45.0, 75.0, 165.0, 195.0, 285.0, 315.0)
OFFSET_BASE = 0.005
OFFSET_PLATFORM = 0.005
HOME_Z = 0.220
STROKE = (0.195, 0.265)
# Table 3: x, y, z (m) and rotations about x, y, z (rad).
WORKSPACE_MIN = (-0.025, -0.025, 0.200, -np.radians(15), -np.radians(15), -np.radians(20))
WORKSPACE_MAX = (0.025, 0.025, 0.240, np.radians(15), np.radians(15), np.radians(20))
# Three SMR nests on the tool plate, 120 deg apart (the paper's datum holes #3, #4, #5).
TARGET_RADIUS = 0.100
TARGET_HEIGHT = 0.015
TARGET_ANGLES_DEG = (90.0, 210.0, 330.0)


def circle_points(radius: float, angles_deg: tuple[float, ...]) -> np.ndarray:
    a = np.radians(angles_deg)
    return np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros_like(a)], axis=1)


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def frame(x: np.ndarray | None = None, y: np.ndarray | None = None, z: np.ndarray | None = None):
    """Rotation matrix with the given orthonormal columns (two of three given)."""
    if x is None:
        x = np.cross(y, z)
    elif y is None:
        y = np.cross(z, x)
    elif z is None:
        z = np.cross(x, y)
    return np.stack([x, y, z], axis=1)


def leg_home(b: np.ndarray, p_world: np.ndarray, x_b: np.ndarray, x_p: np.ndarray):
    """Arms and limb direction of one leg by fixed-point iteration (converges in ~10 steps)."""
    u = unit(p_world - b)
    for _ in range(100):
        a_b = unit(u - (u @ x_b) * x_b)
        a_p = unit(-u - (-u @ x_p) * x_p)
        d = b + OFFSET_BASE * a_b
        c = p_world + OFFSET_PLATFORM * a_p
        u_new = unit(c - d)
        if np.linalg.norm(u_new - u) < 1e-15:
            break
        u = u_new
    return a_b, a_p, d, c, u_new


def quat_wxyz(rot: np.ndarray) -> np.ndarray:
    w = np.sqrt(max(0.0, 1.0 + np.trace(rot))) / 2.0
    if w > 1e-6:
        return canonical_quat(
            [
                w,
                (rot[2, 1] - rot[1, 2]) / (4 * w),
                (rot[0, 2] - rot[2, 0]) / (4 * w),
                (rot[1, 0] - rot[0, 1]) / (4 * w),
            ]
        )
    i = int(np.argmax(np.diag(rot)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = np.sqrt(max(0.0, 1.0 + rot[i, i] - rot[j, j] - rot[k, k])) * 2
    q = np.zeros(4)
    q[0] = (rot[k, j] - rot[j, k]) / s
    q[1 + i] = s / 4
    q[1 + j] = (rot[j, i] + rot[i, j]) / s
    q[1 + k] = (rot[k, i] + rot[i, k]) / s
    return canonical_quat(q)


def build_xml() -> str:
    base = circle_points(BASE_RADIUS, BASE_ANGLES_DEG)
    plat = circle_points(PLATFORM_RADIUS, PLATFORM_ANGLES_DEG)
    home = np.array([0.0, 0.0, HOME_Z])
    z_axis = np.array([0.0, 0.0, 1.0])
    legs, sites, welds, actuators, lengths = [], [], [], [], []
    for i in range(6):
        n = i + 1
        x_b = unit(base[i])
        x_p = unit(plat[i])
        a_b, a_p, d, c, u = leg_home(base[i], home + plat[i], x_b, x_p)
        length = np.linalg.norm(c - d)
        lengths.append(length)
        r_base = frame(x=x_b, z=a_b)  # j1 about local x, arm along local z
        n_b = unit(np.cross(x_b, a_b))
        r_lower = frame(y=n_b, z=u)  # j2 about local y, roll and slide about local z
        n_p = unit(np.cross(x_p, a_p))
        r_top = frame(y=n_p, z=-a_p)  # j5 about local y, arm C_i -> P_i along local z
        r_end = frame(x=x_p, z=z_axis)  # j6 about local x = X_Pi, platform orientation
        q_base = quat_wxyz(r_base)
        q_lower = quat_wxyz(r_base.T @ r_lower)
        q_top = quat_wxyz(r_lower.T @ r_top)
        q_end = quat_wxyz(r_top.T @ r_end)
        legs.append(f"""
    <body name="leg{n}_base" pos="{fmt(base[i])}" quat="{fmt(q_base)}">
      <joint name="leg{n}_base_x" type="hinge" axis="1 0 0"/>
      <geom class="arm" fromto="0 0 0 0 0 {OFFSET_BASE:.12g}"/>
      <body name="leg{n}_lower" pos="0 0 {OFFSET_BASE:.12g}" quat="{fmt(q_lower)}">
        <joint name="leg{n}_base_n" type="hinge" axis="0 1 0"/>
        <joint name="leg{n}_roll" type="hinge" axis="0 0 1"/>
        <geom class="cylinder" fromto="0 0 0 0 0 0.12"/>
        <body name="leg{n}_rod" pos="0 0 {length:.12g}">
          <joint name="leg{n}_slide" type="slide" axis="0 0 1" ref="{length:.12g}" range="{STROKE[0]} {STROKE[1]}"/>
          <geom class="rod" fromto="0 0 -0.13 0 0 0"/>
          <body name="leg{n}_top" quat="{fmt(q_top)}">
            <joint name="leg{n}_top_n" type="hinge" axis="0 1 0"/>
            <geom class="arm" fromto="0 0 0 0 0 {OFFSET_PLATFORM:.12g}"/>
            <body name="leg{n}_end" pos="0 0 {OFFSET_PLATFORM:.12g}" quat="{fmt(q_end)}">
              <joint name="leg{n}_top_x" type="hinge" axis="1 0 0"/>
              <geom class="joint" size="0.006"/>
              <site name="leg{n}_end" size="0.004"/>
            </body>
          </body>
        </body>
      </body>
    </body>""")
        r_site = frame(x=x_p, z=z_axis)
        sites.append(
            f'      <site name="platform_P{n}" pos="{fmt(plat[i])}" quat="{fmt(quat_wxyz(r_site))}" '
            f'size="0.005" rgba="0.9 0.5 0.1 1"/>'
        )
        welds.append(f'    <weld name="leg{n}_closure" site1="leg{n}_end" site2="platform_P{n}"/>')
        actuators.append(
            f'    <position name="leg{n}" joint="leg{n}_slide" kp="2e6" '
            f'ctrlrange="{STROKE[0]} {STROKE[1]}"/>'
        )
    targets = circle_points(TARGET_RADIUS, TARGET_ANGLES_DEG) + [0, 0, TARGET_HEIGHT]
    target_sites = "\n".join(
        f'      <site name="target_{k + 1}" pos="{fmt(t)}" size="0.0095" rgba="0.8 0.8 0.85 1"/>'
        for k, t in enumerate(targets)
    )
    keyframe_qpos = []
    for length in lengths:
        keyframe_qpos += [0, 0, 0, length, 0, 0]
    keyframe_qpos += [0, 0, HOME_Z, 1, 0, 0, 0]
    ws_min, ws_max = fmt(WORKSPACE_MIN), fmt(WORKSPACE_MAX)
    return f"""<!-- 6-RRRPRR hexapod of Han et al. (2019), nominal geometry from its Table 1.
     Generated by models/build_hexapod.py, which explains every number; edit that script.
     Units: metres and radians (MuJoCo's). Actuator values are limb lengths |D_i C_i|.
     Closures: one site-based weld per limb (leg end frame = platform joint frame), so each
     6-joint limb plus the 6-DOF platform is exactly determined once the actuators are held.
     Tracker targets: sites named target_*; the commanded tool frame: site "tool". -->
<mujoco model="hexapod_rrrprr">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.002" integrator="implicitfast">
    <flag contact="disable"/>
  </option>
  <custom>
    <numeric name="workspace_min" data="{ws_min}"/>
    <numeric name="workspace_max" data="{ws_max}"/>
    <numeric name="home_pose" data="0 0 {HOME_Z} 0 0 0"/>
  </custom>
  <default>
    <joint damping="1" armature="0.001"/>
    <geom type="capsule" density="2700" rgba="0.6 0.65 0.7 1"/>
    <default class="arm"><geom size="0.004" rgba="0.3 0.3 0.35 1"/></default>
    <default class="cylinder"><geom size="0.012" density="1500" rgba="0.2 0.4 0.7 1"/></default>
    <default class="rod"><geom size="0.007" density="7800" rgba="0.8 0.8 0.8 1"/></default>
    <default class="joint"><geom type="sphere" rgba="0.3 0.3 0.35 1"/></default>
  </default>
  <worldbody>
    <light pos="0 0 1.5" dir="0 0 -1"/>
    <geom name="base_plate" type="cylinder" pos="0 0 -0.01" size="0.21 0.01" rgba="0.35 0.35 0.4 1"/>
    <site name="base_frame" size="0.01" rgba="1 0 0 1"/>{"".join(legs)}
    <body name="platform" pos="0 0 {HOME_Z}">
      <freejoint name="platform_free"/>
      <geom name="platform_plate" type="cylinder" pos="0 0 0.005" size="0.135 0.005" density="2700"
            rgba="0.75 0.7 0.6 1"/>
      <site name="tool" size="0.006" rgba="0 1 0 1"/>
{chr(10).join(sites)}
{target_sites}
    </body>
  </worldbody>
  <equality>
{chr(10).join(welds)}
  </equality>
  <actuator>
{chr(10).join(actuators)}
  </actuator>
  <keyframe>
    <key name="home" qpos="{fmt(keyframe_qpos)}" ctrl="{fmt(lengths)}"/>
  </keyframe>
</mujoco>
"""


def build_parameters() -> str:
    """The second paper's complete 54-parameter error model, in its order (Eq. 3)."""
    lines = [
        "# Complete error model of the 6-RRRPRR hexapod (Han et al. 2019, Eq. 3): 54 parameters",
        "# in the paper's order dL, dP, dB, dL_B, dL_P. Generated by models/build_hexapod.py.",
        "# kind/element/axis say what each one moves in models/hexapod_rrrprr.xml:",
        "#   leg<i>.length          body_pos of leg<i>_rod along the limb (actuator + structure)",
        "#   leg<i>.platform.d*     site_pos of platform_P<i>, axes of the platform frame O_P",
        "#   leg<i>.base.d*         body_pos of leg<i>_base, axes of the base frame O_B",
        "#   leg<i>.base_offset     body_pos of leg<i>_lower along the base arm B_i D_i (L_B)",
        "#   leg<i>.platform_offset body_pos of leg<i>_end along the platform arm C_i P_i (L_P)",
        'model = "hexapod_rrrprr"',
        "",
    ]
    entries = []
    axes = {"dx": "[1, 0, 0]", "dy": "[0, 1, 0]", "dz": "[0, 0, 1]"}
    for n in range(1, 7):
        entries.append((f"leg{n}.length", "body_pos", f"leg{n}_rod", "[0, 0, 1]"))
    for n in range(1, 7):
        for c, ax in axes.items():
            entries.append((f"leg{n}.platform.{c}", "site_pos", f"platform_P{n}", ax))
    for n in range(1, 7):
        for c, ax in axes.items():
            entries.append((f"leg{n}.base.{c}", "body_pos", f"leg{n}_base", ax))
    for n in range(1, 7):
        entries.append((f"leg{n}.base_offset", "body_pos", f"leg{n}_lower", "[0, 0, 1]"))
    for n in range(1, 7):
        entries.append((f"leg{n}.platform_offset", "body_pos", f"leg{n}_end", "[0, 0, 1]"))
    for name, kind, element, axis in entries:
        lines += [
            "[[parameter]]",
            f'name = "{name}"',
            f'kind = "{kind}"',
            f'element = "{element}"',
            f"axis = {axis}",
            "",
        ]
    return "\n".join(lines)


def main() -> None:
    out = Path(__file__).with_name("hexapod_rrrprr.xml")
    out.write_text(build_xml())
    params = Path(__file__).with_name("hexapod_rrrprr.params.toml")
    params.write_text(build_parameters())
    print(f"wrote {out} and {params}")


if __name__ == "__main__":
    main()
