"""The MJCF of a DH table (``twin.formats.dh_table``) and its error model, one parameter per DH
error.

Bodies, for link i = 1..n (the parent body carries frame i-1; frame 0 is body ``base``):

* modified, T_i = Rx(alpha) Tx(a) Rz(theta) Tz(d): static ``link{i}_dh`` at pos (a, 0, 0),
  quat Rx(alpha) in frame i-1; inside it ``link{i}`` (frame i) at pos (0, 0, d), quat
  Rz(theta), with the joint along or about its z axis;
* standard, T_i = Rz(theta) Tz(d) Tx(a) Rx(alpha): ``link{i}`` at the origin of frame i-1,
  quat Rz(theta), with the joint along or about z; inside it static ``link{i}_dh`` (frame i)
  at pos (a, 0, d), quat Rx(alpha).

The table's theta (R) or d (P) is the body's rotation or offset and the joint's zero is
MuJoCo's ``qpos0`` = 0, so the commanded value q is added to it. The flange (frame n, where
the ``tool`` and ``target_*`` sites are) is ``link{n}`` (modified) or ``link{n}_dh``
(standard). Each DH error is then exactly one kind of ``twin.parameters`` (axes in the
parent body's frame, so both x and z are the DH axes):

* ``link{i}.alpha``: body_rot of link{i}_dh about x;  ``link{i}.a``: body_pos of link{i}_dh
  along x;
* ``link{i}.d``: body_pos along z of link{i} (modified) or link{i}_dh (standard) for R; the
  joint's joint_zero for P;
* ``link{i}.theta``: the joint's joint_zero for R; body_rot of link{i} about z for P;
* ``target_<id>.dx/dy/dz``: site_pos of the reflector in the flange frame (optional);
* ``base.dx/dy/dz``, ``base.rx/ry/rz``: body_pos and body_rot of ``base`` along and about the
  world axes (by default: for readings in the base frame nothing else absorbs the base's
  placement; for tracker-frame readings identify fixes them as redundant with the
  registration).

No inertia is written (kinematics only: compile with MuJoCo's boundmass/boundinertia); the
capsules between frame origins are for viewing, with density 0 and no contacts.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from twin.formats.mjcf_numbers import canonical_quat, fmt, snap
from twin.rotations import quat_multiply

if TYPE_CHECKING:
    from twin.formats.dh import DHSite, DHTable

AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}


def exact(values: ArrayLike) -> str:
    """Like ``fmt`` but with every digit (round trip), for checks below 1e-12."""
    return " ".join(repr(float(x)) for x in np.atleast_1d(snap(values)))


def _rot(axis: str, angle: float) -> np.ndarray:
    q = np.zeros(4)
    q[0], q["xyz".index(axis) + 1] = math.cos(angle / 2), math.sin(angle / 2)
    return q


def _rpy_quat(rpy: tuple[float, float, float]) -> np.ndarray:
    """R = Rz(rz) Ry(ry) Rx(rx)."""
    return quat_multiply(quat_multiply(_rot("z", rpy[2]), _rot("y", rpy[1])), _rot("x", rpy[0]))


def flange_body(table: DHTable) -> str:
    n = len(table.joints)
    return f"link{n}" if table.convention == "modified" else f"link{n}_dh"


class _Writer:
    def __init__(self, number: Callable[[ArrayLike], str]) -> None:
        self.number = number
        self.lines: list[str] = []

    def frame(self, pos: ArrayLike, quat: ArrayLike | None = None) -> str:
        out = ""
        pos = snap(pos)
        if np.any(pos):
            out += f' pos="{self.number(pos)}"'
        if quat is not None:
            q = canonical_quat(quat)
            if not np.array_equal(q, [1.0, 0.0, 0.0, 0.0]):
                out += f' quat="{self.number(q)}"'
        return out

    def add(self, depth: int, text: str) -> None:
        self.lines.append("  " * depth + text)

    def segment(self, depth: int, end: ArrayLike) -> None:
        end = snap(end)
        if float(np.linalg.norm(end)) > 1e-9:
            self.add(depth, f'<geom fromto="0 0 0 {self.number(end)}"/>')


def _joint(w: _Writer, depth: int, j) -> None:
    kind = "hinge" if j.type == "R" else "slide"
    rng = w.number([j.lower, j.upper])
    w.add(depth, f'<joint name="{j.name}" type="{kind}" axis="0 0 1" range="{rng}"/>')


def _sites(w: _Writer, depth: int, table: DHTable) -> None:
    tool = table.tool
    w.segment(depth, tool.pos)
    w.add(depth, f'<site name="tool"{w.frame(tool.pos, _rpy_quat(tool.rpy))} rgba="1 0.2 0.2 1"/>')
    for t in table.targets:
        w.add(depth, f'<site name="{t.name}"{w.frame(t.pos)} rgba="0.1 0.8 0.2 1"/>')


def _chain(w: _Writer, table: DHTable) -> int:
    """Write the bodies from base to flange, left open; returns the flange's depth."""
    depth, joints = 2, table.joints
    modified = table.convention == "modified"
    base: DHSite = table.base
    w.add(depth, f'<body name="base"{w.frame(base.pos, _rpy_quat(base.rpy))}>')
    if modified:
        w.segment(depth + 1, [joints[0].a, 0, 0])
    for i, j in enumerate(joints, start=1):
        rz = _rot("z", j.theta)
        depth += 1
        if modified:
            w.add(depth, f'<body name="link{i}_dh"{w.frame([j.a, 0, 0], _rot("x", j.alpha))}>')
            w.segment(depth + 1, [0, 0, j.d])
            depth += 1
            w.add(depth, f'<body name="link{i}"{w.frame([0, 0, j.d], rz)}>')
            _joint(w, depth + 1, j)
            if i < len(joints):
                w.segment(depth + 1, [joints[i].a, 0, 0])
        else:
            w.add(depth, f'<body name="link{i}"{w.frame([0, 0, 0], rz)}>')
            _joint(w, depth + 1, j)
            w.segment(depth + 1, [0, 0, j.d])
            if abs(j.a) > 1e-9:
                w.add(depth + 1, f'<geom fromto="{w.number([0, 0, j.d, j.a, 0, j.d])}"/>')
            depth += 1
            w.add(depth, f'<body name="link{i}_dh"{w.frame([j.a, 0, j.d], _rot("x", j.alpha))}>')
    _sites(w, depth + 1, table)
    return depth


def _reach(table: DHTable) -> float:
    return sum(abs(j.a) + abs(j.d) for j in table.joints) + float(np.linalg.norm(table.tool.pos))


def build_xml(table: DHTable, name: str, number: Callable[[ArrayLike], str] = fmt) -> str:
    """The MJCF text (metres, radians); ``number=exact`` writes every digit."""
    w = _Writer(number)
    source = Path(table.source).name
    w.lines += [
        f"<!-- {name}: a serial arm from the {table.convention}-DH table {source}.",
        "     Generated by pkm-calib from-dh (twin/formats/dh_mjcf.py explains the bodies and",
        "     the error model); edit the table, not this file.",
        "     Units: metres and radians. Joint values add to the table's theta (R) or d (P).",
        "     No inertia: kinematics only (compile with boundmass/boundinertia). -->",
        f'<mujoco model="{name}">',
        '  <compiler angle="radian" autolimits="true"/>',
        '  <option><flag contact="disable"/></option>',
        "  <default>",
        f'    <geom type="capsule" size="{number(0.02 * _reach(table))}" density="0" '
        'contype="0" conaffinity="0" group="1" rgba="0.6 0.62 0.66 1"/>',
        f'    <site size="{number(0.006 * _reach(table))}"/>',
        "  </default>",
        "  <worldbody>",
    ]
    deepest = _chain(w, table)
    w.lines += ["  " * d + "</body>" for d in range(deepest, 1, -1)]
    w.lines += ["  </worldbody>", "  <actuator>"]
    w.lines += [f'    <motor name="{j.name}" joint="{j.name}"/>' for j in table.joints]
    home = number([j.home for j in table.joints])
    w.lines += ["  </actuator>", "  <keyframe>", f'    <key name="home" qpos="{home}"/>']
    w.lines += ["  </keyframe>", "</mujoco>", ""]
    return "\n".join(w.lines)


def parameter_entries(
    table: DHTable, target_errors: bool = True, base_errors: bool = True
) -> list[tuple[str, str, str, tuple[int, int, int]]]:
    """(name, kind, element, axis) of every error-model entry, in file order."""
    out: list[tuple[str, str, str, tuple[int, int, int]]] = []
    if base_errors:
        out += [(f"base.d{c}", "body_pos", "base", a) for c, a in AXES.items()]
        out += [(f"base.r{c}", "body_rot", "base", a) for c, a in AXES.items()]
    modified = table.convention == "modified"
    for i, j in enumerate(table.joints, start=1):
        p, dh = f"link{i}", f"link{i}_dh"
        out += [(f"{p}.alpha", "body_rot", dh, AXES["x"]), (f"{p}.a", "body_pos", dh, AXES["x"])]
        if j.type == "R":
            out.append((f"{p}.d", "body_pos", p if modified else dh, AXES["z"]))
            out.append((f"{p}.theta", "joint_zero", j.name, (0, 0, 0)))
        else:
            out.append((f"{p}.d", "joint_zero", j.name, (0, 0, 0)))
            out.append((f"{p}.theta", "body_rot", p, AXES["z"]))
    if target_errors:
        for t in table.targets:
            out += [(f"{t.name}.d{c}", "site_pos", t.name, a) for c, a in AXES.items()]
    return out


def parallel_pairs(table: DHTable) -> list[tuple[int, int]]:
    """Consecutive revolute joints (i, i+1) with parallel axes: their d errors act alike."""
    js = table.joints
    out = []
    for i in range(1, len(js)):
        alpha = js[i].alpha if table.convention == "modified" else js[i - 1].alpha
        if abs(math.sin(alpha)) < 1e-9 and js[i - 1].type == js[i].type == "R":
            out.append((i, i + 1))
    return out


def build_parameters(
    table: DHTable, name: str, target_errors: bool = True, base_errors: bool = True
) -> str:
    """The error model (TOML): four DH errors per link, the reflectors' offsets and the
    base's placement unless left out."""
    lines = [
        f"# Error model of {name} from the {table.convention}-DH table {Path(table.source).name},",
        "# generated by pkm-calib from-dh (twin/formats/dh_mjcf.py says what each entry moves).",
        "# link<i>.alpha, .a, .d, .theta: the errors of row i of the table (deg, mm in value",
        "# files); target_<id>.d*: reflector offsets in the flange frame; base.*: base pose.",
    ]
    for i, k in parallel_pairs(table):
        lines.append(
            f"# joints {i} and {k} are parallel: link{i}.d and link{k}.d act alike "
            "(one of them is unidentifiable)."
        )
    lines += [f'model = "{name}"', ""]
    for pname, kind, element, axis in parameter_entries(table, target_errors, base_errors):
        lines += [
            "[[parameter]]",
            f'name = "{pname}"',
            f'kind = "{kind}"',
            f'element = "{element}"',
        ]
        if kind != "joint_zero":
            lines.append(f"axis = [{axis[0]}, {axis[1]}, {axis[2]}]")
        lines.append("")
    return "\n".join(lines)
