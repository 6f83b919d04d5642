"""Writes models/polisher.xml and its complete source-error model (run: python models/build_polisher.py).

The 6-DOF hybrid polishing robot of Huang et al. (2018): a 3-UPS + UP parallel mechanism
carrying a 3-DOF wrist (actuated R joints theta4..theta6) with the polishing head and a
triangle gauge of three tracker targets. The XML is the single source of truth for the shape;
this script documents how its numbers were chosen, and a test checks that the committed
files equal its output.

Frames and world. The MJCF world is the workpiece frame {R} of the paper (z normal to the
worktable, y parallel to x0); its origin is the centre of the 500 x 500 x 120 mm task
workspace, where the head's reference point P sits at the reference pose. The base frame
{R0} at A0 has orientation wR0 = Rot(y, pi - beta) Rot(z, pi/2) with beta = pi/6 (Eq. 8).

From the paper's Table 1 (mm): |A4,4 A6,4| = e = 345, |A4,4 A6,i| = 135, |A6,4 Q| = 405,
|Q P0| = 120, |P0 P| = 250, |P0 Pi| = 200, UPS limb stroke 628..1178. Where the paper is
silent, these choices (each documented in the XML too):
* the UPS limbs' U joints A1,i lie on a 350 mm circle around A0 in the base plane (Table 1's
  350 read as that circumradius); limb 1 lies in the robot's symmetry plane (the x-z plane of
  {R}, which contains the tilt), limbs 2 and 3 at +-120 deg, so that limbs 2 and 3 are
  mirror images, as the paper's Table 2 says;
* the S joints A6,i lie on the 135 mm circle around A4,4 in the plane normal to the UP limb,
  at the same angles as the U joints;
* the UP limb length at the reference pose is 850 mm, which puts the three UPS limbs at
  877 mm; over the task workspace in pure translation they then run 649..1158 mm, inside
  the 628..1178 mm stroke (with the limbs at mid-stroke, 903 mm, one corner needed 1182 mm);
  the UP limb's passive stroke is 600..1200 mm (it runs 690..1062 mm), the wrist angles
  stay within +-15 deg (their range is +-90 deg);
* the S joints as three R joints: z4,i parallel to the U joint's second axis z2,i, z5,i
  normal to it and to the limb, z6,i along the limb (reference pose). The layout matters:
  with z4,i along the limb instead, the offsets inside an S joint only lengthen the limb,
  and 44 instead of 51 source-error combinations are identifiable from the paper's plan;
* the wrist: z4,4 along the UP limb, z5,4 and z6,4 intersecting at A6,4 = A4,4 + e u; at the
  reference pose z5,4 is along y and z6,4 along x of {R} (section 3);
* the head: A6,4 -> Q 405 mm along -z, Q -> P0 120 mm along +x, P0 -> P 250 mm along -z at
  the reference pose (tool axis vertical); the gauge targets P1 = P0 + 200 y and
  P2, P3 = P0 + 200 (-+cos 30, -sin 30, 0): the triangle is normal to P0P, P0P1 along y and
  P2P3 along x, as section 3 asks;
* A0 then follows from P = 0 at the reference pose: A0 = -(c u + (120, 0, -655) mm) with
  c = 850 + 345 mm and u the UP limb direction, z0 of {R0}.
Joint frames follow Appendix A: one body per 1-DOF joint with its z axis along the joint
axis (U = two R, S = three R joints), so that each body's position and orientation errors are
the paper's structural errors of that joint frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from twin.formats.mjcf_numbers import canonical_quat, fmt

BETA = np.pi / 6
BASE_RADIUS = 0.350
PLATFORM_RADIUS = 0.135
E_WRIST = 0.345
A64_Q = 0.405
Q_P0 = 0.120
P0_P = 0.250
GAUGE_RADIUS = 0.200
UPS_STROKE = (0.628, 1.178)
UP_STROKE = (0.600, 1.200)
UP_LENGTH_REF = 0.850
WRIST_RANGE = np.radians(90.0)
LIMB_ANGLES_DEG = (90.0, 210.0, 330.0)  # in the base plane, from x0
WORKSPACE_HALF = (0.250, 0.250, 0.060)


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def frame_z(z: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Rotation whose z column is ``z`` and x column is ``x_hint`` made orthogonal to it."""
    z = unit(z)
    x = unit(x_hint - (x_hint @ z) * z)
    return np.stack([x, np.cross(z, x), z], axis=1)


def quat_wxyz(rot: np.ndarray) -> np.ndarray:
    m = rot
    t = np.trace(m)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k]) * 2
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q = np.array(q)
    return canonical_quat(q)


class Geometry:
    """Every frame of the robot at the reference pose, in {R}."""

    def __init__(self) -> None:
        self.w_r0 = rot_y(np.pi - BETA) @ rot_z(0.5 * np.pi)
        self.u = self.w_r0[:, 2]  # UP limb direction at the reference pose
        x_r, y_r, z_r = np.eye(3)
        c = UP_LENGTH_REF + E_WRIST
        head = A64_Q * -z_r + Q_P0 * x_r + P0_P * -z_r  # A6,4 -> P
        self.a0 = -(c * self.u + head)
        self.a44 = self.a0 + UP_LENGTH_REF * self.u
        self.a64 = self.a44 + E_WRIST * self.u
        self.q = self.a64 + A64_Q * -z_r
        self.p0 = self.q + Q_P0 * x_r
        self.p = self.p0 + P0_P * -z_r
        self.targets = [
            self.p0 + GAUGE_RADIUS * y_r,
            self.p0 + GAUGE_RADIUS * np.array([-np.cos(np.pi / 6), -np.sin(np.pi / 6), 0.0]),
            self.p0 + GAUGE_RADIUS * np.array([np.cos(np.pi / 6), -np.sin(np.pi / 6), 0.0]),
        ]
        self.a1, self.a6 = [], []
        for ang in np.radians(LIMB_ANGLES_DEG):
            radial = self.w_r0 @ np.array([np.cos(ang), np.sin(ang), 0.0])
            self.a1.append(self.a0 + BASE_RADIUS * radial)
            self.a6.append(self.a44 + PLATFORM_RADIUS * radial)
        self.ups_lengths = [
            float(np.linalg.norm(b - a)) for a, b in zip(self.a1, self.a6, strict=True)
        ]


def body(name, pos, rot_parent, rot, joint=None, extra="", children="", indent=4):
    """One body: position in the parent frame, orientation relative to the parent."""
    pad = " " * indent
    q = quat_wxyz(rot_parent.T @ rot)
    lines = [f'{pad}<body name="{name}" pos="{fmt(pos)}" quat="{fmt(q)}">']
    if joint:
        lines.append(f"{pad}  {joint}")
    if extra:
        lines.append(extra)
    if children:
        lines.append(children)
    lines.append(f"{pad}</body>")
    return "\n".join(lines)


def build_xml() -> str:
    g = Geometry()
    x_r, y_r, z_r = np.eye(3)
    w_r0 = g.w_r0
    eye = np.eye(3)
    ups = []
    welds = []
    platform_sites = []
    for i in range(3):
        n = i + 1
        a1, a6 = g.a1[i], g.a6[i]
        radial = unit(a1 - g.a0)
        tangent = np.cross(w_r0[:, 2], radial)
        limb = unit(a6 - a1)
        length = np.linalg.norm(a6 - a1)
        r_f0 = np.stack([radial, tangent, w_r0[:, 2]], axis=1)
        r_j1 = frame_z(tangent, radial)
        r_j2 = frame_z(np.cross(limb, tangent), tangent)
        r_j3 = frame_z(limb, r_j2[:, 2])
        # S joint as three R joints: the first parallel to the U joint's second axis, the
        # last along the limb (with the first along the limb instead, the offsets inside the
        # S joint only lengthen the limb and the identifiable count drops from 51 to 44)
        r_j4 = frame_z(r_j2[:, 2], limb)
        r_j5 = frame_z(np.cross(limb, r_j2[:, 2]), limb)
        r_j6 = frame_z(limb, r_j2[:, 2])
        ind = 10
        j6 = body(
            f"limb{n}_j6",
            [0, 0, 0],
            r_j5,
            r_j6,
            f'<joint name="limb{n}_j6" type="hinge" axis="0 0 1"/>',
            extra=f'{" " * (ind + 10)}<site name="limb{n}_end" size="0.01"/>',
            indent=ind + 8,
        )
        j5 = body(
            f"limb{n}_j5",
            [0, 0, 0],
            r_j4,
            r_j5,
            f'<joint name="limb{n}_j5" type="hinge" axis="0 0 1"/>',
            children=j6,
            indent=ind + 6,
        )
        j4 = body(
            f"limb{n}_j4",
            [0, 0, 0],
            r_j3,
            r_j4,
            f'<joint name="limb{n}_j4" type="hinge" axis="0 0 1"/>',
            extra=f'{" " * (ind + 6)}<geom class="ball" size="0.03"/>',
            children=j5,
            indent=ind + 4,
        )
        j3 = body(
            f"limb{n}_j3",
            r_j2.T @ (a6 - a1),
            r_j2,
            r_j3,
            f'<joint name="limb{n}_j3" type="slide" axis="0 0 1" ref="{length:.12g}" '
            f'range="{UPS_STROKE[0]} {UPS_STROKE[1]}"/>',
            extra=f'{" " * (ind + 4)}<geom class="rod" fromto="0 0 -0.55 0 0 0"/>',
            children=j4,
            indent=ind + 2,
        )
        j2 = body(
            f"limb{n}_j2",
            [0, 0, 0],
            r_j1,
            r_j2,
            f'<joint name="limb{n}_j2" type="hinge" axis="0 0 1"/>',
            extra=f'{" " * (ind + 2)}<geom class="cylinder" fromto="0 0 0 '
            f'{fmt(r_j2.T @ limb * 0.6)}"/>',
            children=j3,
            indent=ind,
        )
        j1 = body(
            f"limb{n}_j1",
            [0, 0, 0],
            r_f0,
            r_j1,
            f'<joint name="limb{n}_j1" type="hinge" axis="0 0 1"/>',
            children=j2,
            indent=ind - 2,
        )
        f0 = body(
            f"limb{n}_frame0",
            w_r0.T @ (a1 - g.a0),
            w_r0,
            r_f0,
            extra=f'{" " * (ind - 2)}<geom class="ball" size="0.04"/>',
            children=j1,
            indent=ind - 4,
        )
        ups.append(f0)
        # platform S-joint site with the same frame as limb n's last joint body
        platform_sites.append((n, a6, r_j6))
        welds.append(
            f'    <weld name="limb{n}_closure" site1="limb{n}_end" site2="platform_S{n}"/>'
        )

    # UP limb + wrist + head
    r_f04 = w_r0
    r_j14 = frame_z(w_r0[:, 0], w_r0[:, 1])
    r_j24 = frame_z(w_r0[:, 1], w_r0[:, 2])
    r_j34 = frame_z(g.u, w_r0[:, 0])
    r_j44 = frame_z(g.u, w_r0[:, 0])
    r_j54 = frame_z(y_r, x_r)
    r_j64 = frame_z(x_r, -z_r)
    r_head = eye
    head_extra = "\n".join(
        [
            f'{" " * 24}<geom class="head" fromto="0 0 0 {fmt(r_head.T @ (g.q - g.a64))}"/>',
            f'{" " * 24}<geom class="head" fromto="{fmt(g.q - g.a64)} {fmt(g.p0 - g.a64)}"/>',
            f'{" " * 24}<geom class="tool" fromto="{fmt(g.p0 - g.a64)} {fmt(g.p - g.a64)}"/>',
            f'{" " * 24}<site name="tool" pos="{fmt(g.p - g.a64)}" size="0.01" rgba="0 1 0 1"/>',
            f'{" " * 24}<site name="P0" pos="{fmt(g.p0 - g.a64)}" size="0.008"/>',
        ]
        + [
            f'{" " * 24}<site name="target_{k + 1}" pos="{fmt(t - g.a64)}" size="0.0095" '
            f'rgba="0.8 0.8 0.85 1"/>'
            for k, t in enumerate(g.targets)
        ]
        + [
            f'{" " * 24}<geom class="gauge" fromto="{fmt(g.p0 - g.a64)} {fmt(t - g.a64)}"/>'
            for t in g.targets
        ]
    )
    head = body("head", [0, 0, 0], r_j64, r_head, extra=head_extra, indent=22)
    j64 = body(
        "limb4_j6",
        r_j54.T @ (g.a64 - g.a64),
        r_j54,
        r_j64,
        f'<joint name="limb4_j6" type="hinge" axis="0 0 1" '
        f'range="{-WRIST_RANGE:.12g} {WRIST_RANGE:.12g}"/>',
        children=head,
        indent=20,
    )
    j54 = body(
        "limb4_j5",
        r_j44.T @ (g.a64 - g.a44),
        r_j44,
        r_j54,
        f'<joint name="limb4_j5" type="hinge" axis="0 0 1" '
        f'range="{-WRIST_RANGE:.12g} {WRIST_RANGE:.12g}"/>',
        extra=f'{" " * 20}<geom class="ball" size="0.05"/>',
        children=j64,
        indent=18,
    )
    sites = "\n".join(
        f'{" " * 18}<site name="platform_S{n}" pos="{fmt(r_j34.T @ (a6 - g.a44))}" '
        f'quat="{fmt(quat_wxyz(r_j34.T @ r))}" size="0.012" rgba="0.9 0.5 0.1 1"/>'
        for n, a6, r in platform_sites
    )
    j44 = body(
        "limb4_j4",
        [0, 0, 0],
        r_j34,
        r_j44,
        f'<joint name="limb4_j4" type="hinge" axis="0 0 1" '
        f'range="{-WRIST_RANGE:.12g} {WRIST_RANGE:.12g}"/>',
        extra=f'{" " * 18}<geom class="wrist" fromto="0 0 0 0 0 {E_WRIST:.12g}"/>',
        children=j54,
        indent=16,
    )
    platform = body(
        "limb4_j3",
        r_j24.T @ (g.a44 - g.a0),
        r_j24,
        r_j34,
        f'<joint name="limb4_j3" type="slide" axis="0 0 1" ref="{UP_LENGTH_REF:.12g}" '
        f'range="{UP_STROKE[0]} {UP_STROKE[1]}"/>',
        extra=f'{" " * 16}<geom name="platform" class="platform" fromto="0 0 -0.02 0 0 0.02"/>\n'
        f'{" " * 16}<geom class="rod" fromto="0 0 -0.6 0 0 0"/>\n{sites}',
        children=j44,
        indent=14,
    )
    j24 = body(
        "limb4_j2",
        [0, 0, 0],
        r_j14,
        r_j24,
        '<joint name="limb4_j2" type="hinge" axis="0 0 1"/>',
        children=platform,
        indent=12,
    )
    j14 = body(
        "limb4_j1",
        [0, 0, 0],
        r_f04,
        r_j14,
        '<joint name="limb4_j1" type="hinge" axis="0 0 1"/>',
        children=j24,
        indent=10,
    )
    f04 = body(
        "limb4_frame0",
        [0, 0, 0],
        w_r0,
        r_f04,
        extra=f'{" " * 10}<geom class="ball" size="0.05"/>',
        children=j14,
        indent=8,
    )
    base = body(
        "base",
        g.a0,
        eye,
        w_r0,
        extra=f'{" " * 8}<geom name="base_plate" type="cylinder" size="0.42 0.02" '
        f'pos="0 0 -0.06" rgba="0.35 0.35 0.4 1"/>\n'
        f'{" " * 8}<site name="A0" size="0.015" rgba="1 0 0 1"/>',
        children="\n".join([f04, *ups]),
        indent=4,
    )
    qpos = []
    for length in g.ups_lengths:
        qpos += [0, 0, length, 0, 0, 0]
    qpos_up = [0, 0, UP_LENGTH_REF, 0, 0, 0]
    key_qpos = qpos_up + qpos  # body order: limb4 chain is declared first under base
    ctrl = [*g.ups_lengths, 0, 0, 0]
    hx, hy, hz = WORKSPACE_HALF
    return f"""<!-- 6-DOF hybrid polishing robot of Huang et al. (2018): 3-UPS + UP parallel mechanism
     with a 3-DOF wrist. Generated by models/build_polisher.py, which explains every number
     and every choice where the paper is silent; edit that script, not this file.
     World = the workpiece frame {{R}} (origin: centre of the 500 x 500 x 120 mm task
     workspace; the head point P is there at the reference pose). Units: metres, radians.
     Actuators: the three UPS limb lengths q1..q3 (|A1,i A6,i|) and the wrist angles
     theta4..theta6. Closures: one site-based weld per UPS limb (its S joint is three R joints).
     Paper (Table 1, mm): e = |A4,4 A6,4| = 345, |A4,4 A6,i| = 135, |A6,4 Q| = 405, |Q P0| = 120,
     |P0 P| = 250, |P0 Pi| = 200, UPS stroke 628..1178; beta = pi/6 (Eq. 8).
     Chosen where the paper is silent, and why:
     * U joints A1,i on a 350 mm circle around A0 (Table 1's 350 read as that circumradius),
       at 90/210/330 deg from x0: limb 1 in the symmetry plane (x-z of {{R}}), limbs 2 and 3
       mirror images of each other, as the paper's Table 2 requires;
     * S joints A6,i on the 135 mm circle around A4,4, normal to the UP limb, same angles;
     * UP limb {UP_LENGTH_REF * 1e3:.0f} mm at the reference pose, so the UPS limbs measure
       {g.ups_lengths[0] * 1e3:.3f} mm there and 649..1158 mm over the whole task workspace
       (inside 628..1178; at mid-stroke one corner needed 1182 mm);
     * S joints as three R joints: z4,i parallel to the U joint's second axis, z6,i along the
       limb (with z4,i along the limb, S-joint offsets only lengthen it: fewer identifiable);
     * wrist: z4,4 along the UP limb; z5,4 (along y) and z6,4 (along x) meet at A6,4;
     * head: A6,4 -> Q along -z, Q -> P0 along +x, P0 -> P along -z at the reference pose;
       gauge targets P1 = P0 + 200 y, P2,3 = P0 + 200 (-+cos30, -sin30, 0): the triangle is
       normal to P0P with P0P1 along y and P2P3 along x (section 3);
     * A0 placed so that P is at the workspace centre at the reference pose. -->
<mujoco model="polisher">
  <!-- joint bodies of U and S joints carry no geometry: a small bound mass keeps them valid -->
  <compiler angle="radian" autolimits="true" boundmass="0.05" boundinertia="1e-5"/>
  <option timestep="0.002" integrator="implicitfast">
    <flag contact="disable"/>
  </option>
  <custom>
    <!-- task workspace: the head in pure translation (rotations fixed at zero) -->
    <numeric name="workspace_min" data="{fmt([-hx, -hy, -hz, 0, 0, 0])}"/>
    <numeric name="workspace_max" data="{fmt([hx, hy, hz, 0, 0, 0])}"/>
    <numeric name="home_pose" data="0 0 0 0 0 0"/>
    <numeric name="beta" data="{BETA:.12g}"/>
  </custom>
  <default>
    <joint damping="5" armature="0.01"/>
    <geom type="capsule" density="2700" rgba="0.6 0.65 0.7 1"/>
    <default class="ball"><geom type="sphere" rgba="0.3 0.3 0.35 1"/></default>
    <default class="cylinder"><geom size="0.04" density="1200" rgba="0.2 0.4 0.7 1"/></default>
    <default class="rod"><geom size="0.025" density="7800" rgba="0.8 0.8 0.8 1"/></default>
    <default class="platform"><geom type="cylinder" size="0.17" density="2700" rgba="0.75 0.7 0.6 1"/></default>
    <default class="wrist"><geom size="0.05" density="2700" rgba="0.5 0.5 0.55 1"/></default>
    <default class="head"><geom size="0.05" density="2700" rgba="0.7 0.5 0.3 1"/></default>
    <default class="tool"><geom size="0.03" density="2700" rgba="0.9 0.9 0.9 1"/></default>
    <default class="gauge"><geom size="0.006" density="2700" rgba="0.2 0.2 0.2 1"/></default>
  </default>
  <worldbody>
    <light pos="0 0 3" dir="0 0 -1"/>
    <geom name="worktable" type="box" pos="0 0 -0.36" size="0.6 0.6 0.02" rgba="0.3 0.3 0.3 1"/>
    <site name="workspace_centre" size="0.01" rgba="1 0 0 1"/>
{base}
  </worldbody>
  <equality>
{chr(10).join(welds)}
  </equality>
  <actuator>
    <position name="q1" joint="limb1_j3" kp="1e6" ctrlrange="{UPS_STROKE[0]} {UPS_STROKE[1]}"/>
    <position name="q2" joint="limb2_j3" kp="1e6" ctrlrange="{UPS_STROKE[0]} {UPS_STROKE[1]}"/>
    <position name="q3" joint="limb3_j3" kp="1e6" ctrlrange="{UPS_STROKE[0]} {UPS_STROKE[1]}"/>
    <position name="theta4" joint="limb4_j4" kp="1e5"/>
    <position name="theta5" joint="limb4_j5" kp="1e5"/>
    <position name="theta6" joint="limb4_j6" kp="1e5"/>
  </actuator>
  <keyframe>
    <key name="home" qpos="{fmt(key_qpos)}" ctrl="{fmt(ctrl)}"/>
  </keyframe>
</mujoco>
"""


AXES = {"dx": (1, 0, 0), "dy": (0, 1, 0), "dz": (0, 0, 1)}
ROTS = {"dalpha": (1, 0, 0), "dbeta": (0, 1, 0), "dgamma": (0, 0, 1)}


def source_errors() -> list[tuple[str, str, str, tuple[float, float, float]]]:
    """The complete source errors of Appendix A: (name, kind, element, axis in parent frame).

    Base frame of each limb: 6 errors; every 1-DOF joint frame: the 6 components less the one
    along (P joint: dz) or about (R joint: dgamma) its own axis; encoder offsets of the three
    P joints and three wrist R joints. Axes are the joint frame's own, written in the parent
    body's frame (as the injection expects).
    """
    import mujoco

    model = mujoco.MjModel.from_xml_string(build_xml())
    out = []

    def frame_axes(body_name: str) -> np.ndarray:
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name)
        w, x, y, z = model.body_quat[b]
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )

    def add_frame(prefix: str, body_name: str, skip: str | None) -> None:
        r = frame_axes(body_name)
        for comp, e in AXES.items():
            if comp != skip:
                out.append((f"{prefix}.{comp}", "body_pos", body_name, tuple(r @ np.array(e))))
        for comp, e in ROTS.items():
            if comp != skip:
                out.append((f"{prefix}.{comp}", "body_rot", body_name, tuple(r @ np.array(e))))

    for i in (1, 2, 3, 4):
        add_frame(f"limb{i}.j0", f"limb{i}_frame0", None)
        last = 6
        for j in range(1, last + 1):
            prismatic = j == 3
            add_frame(f"limb{i}.j{j}", f"limb{i}_j{j}", "dz" if prismatic else "dgamma")
    for i in (1, 2, 3):
        out.append((f"limb{i}.j3.encoder", "joint_zero", f"limb{i}_j3", (0.0, 0.0, 0.0)))
    for j in (4, 5, 6):
        out.append((f"limb4.j{j}.encoder", "joint_zero", f"limb4_j{j}", (0.0, 0.0, 0.0)))
    return out


def build_parameters() -> str:
    errs = source_errors()
    lines = [
        "# Complete source errors of the hybrid polishing robot (Huang et al. 2018, Appendix A).",
        "# Generated by models/build_polisher.py. Names: limb<i>.j<j>.<component>: the error of",
        "# joint frame {R_j,i} (j = 0: the limb's base frame) along/about its own x, y, z axes",
        "# (dx, dy, dz, dalpha, dbeta, dgamma); the component along (P) or about (R) the joint",
        "# axis is left out, being the joint variable itself. limb4 j4..j6 is the wrist.",
        "# limb<i>.j<j>.encoder: encoder offsets of the actuated joints (mm or deg in files).",
        f"# Count: {len(errs)} (the paper states 145; see docs in models/build_polisher.py).",
        'model = "polisher"',
        "",
    ]
    for name, kind, element, axis in errs:
        lines += [
            "[[parameter]]",
            f'name = "{name}"',
            f'kind = "{kind}"',
            f'element = "{element}"',
            f"axis = [{', '.join(fmt(axis).split())}]",
            "",
        ]
    return "\n".join(lines)


def main() -> None:
    out = Path(__file__).with_name("polisher.xml")
    out.write_text(build_xml())
    params = Path(__file__).with_name("polisher.params.toml")
    params.write_text(build_parameters())
    print(f"wrote {out} and {params}")


if __name__ == "__main__":
    main()
