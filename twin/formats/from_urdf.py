"""A machine model and its complete error model from a URDF, one command.

    pkm-calib from-urdf robot.urdf --target target_1=LINK[@x,y,z] [--target ...]
        [--tool LINK[@x,y,z[,rx,ry,rz]]] [--name NAME] --out-dir DIR

writes ``DIR/<robot>.xml`` and ``DIR/<robot>.params.toml`` (atomically; nothing when an
input is wrong). The MJCF holds the URDF's kinematic tree as MuJoCo compiles it (every link
a body, fixed joints included; positions and orientations with every digit), its inertials
where the URDF gives them, one ``position`` actuator per movable joint named after the joint
(its command is the joint's value, in radians or metres as in the URDF), a ``target_*`` site
per reflector on the named link at the given offset (mm, in the link's frame; at its origin
without one), a ``tool`` site (default: at the origin of the first reflector's link), a
``home`` keyframe (every joint at 0, or at the middle of a range without 0), and capsules
between joint origins for viewing (the URDF's visual and collision meshes are left out).
The error model is ``twin.formats.error_model``'s complete one. ``--name`` renames the model (the
name datasets give in their ``model`` field; default: the URDF's robot name, so a dataset
recorded under another name is refused until the model is made with ``--name`` that name).
Existing files are not replaced without ``--force``. Refused, with the cause: a NaN or
infinite number, a prismatic joint without ``<limit>``, a limit whose lower is above its
upper, a chain deeper than 100 links.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from twin.exceptions import TwinError
from twin.formats.error_model import error_model_toml
from twin.formats.mjcf_values import exact
from twin.formats.model_files import out_files, write_model_files
from twin.formats.urdf_import import Urdf, UrdfError, body_of_link, read_urdf
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rpy, quat_from_matrix

_TARGET = re.compile(r"target_[A-Za-z0-9_]+$")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*$")
KP = 1e4  # placeholder servo gain of the position actuators (kinematics does not use it)


@dataclass(frozen=True)
class SiteSpec:
    """A site on a link: position (m) and rotation (quat) in the link's frame."""

    name: str
    link: str
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


def _numbers(text: str, what: str, counts: tuple[int, ...]) -> list[float]:
    cells = [c.strip() for c in text.split(",")]
    try:
        values = [float(c) for c in cells]
    except ValueError:
        values = []
    if len(values) not in counts or not all(math.isfinite(v) for v in values):
        need = " or ".join(str(n) for n in counts)
        raise UrdfError(f"{what}: '{text}' is not {need} numbers separated by commas")
    return values


def parse_site(text: str, what: str, named: bool) -> SiteSpec:
    """``NAME=LINK[@x,y,z]`` (a reflector) or ``LINK[@x,y,z[,rx,ry,rz]]`` (the tool); mm,
    deg."""
    name = "tool"
    if named:
        if "=" not in text:
            raise UrdfError(
                f"{what} '{text}': write NAME=LINK[@x,y,z] (e.g. target_1=tool0@0,0,50)"
            )
        name, text = (s.strip() for s in text.split("=", 1))
        if not _TARGET.match(name):
            raise UrdfError(f"{what} '{name}': a reflector's name is target_<letters, digits, _>")
    link, _, offset = text.partition("@")
    link = link.strip()
    if not link:
        raise UrdfError(f"{what} '{text}': no link named")
    if not offset:
        return SiteSpec(name, link, (0.0, 0.0, 0.0))
    values = _numbers(offset, f"{what} {name}={text}: the offset", (3,) if named else (3, 6))
    pos = tuple(v * 1e-3 for v in values[:3])
    quat = (1.0, 0.0, 0.0, 0.0)
    if len(values) == 6:
        quat = tuple(quat_from_matrix(matrix_from_rpy(np.radians(values[3:]))).tolist())
    return SiteSpec(name, link, pos, quat)  # type: ignore[arg-type]


def _home(m: mujoco.MjModel, j: int) -> float:
    lo, hi = m.jnt_range[j]
    return 0.0 if not m.jnt_limited[j] or lo <= 0.0 <= hi else 0.5 * (lo + hi)


def _reach(m: mujoco.MjModel) -> float:
    return float(np.sum(np.linalg.norm(m.body_pos[1:], axis=1))) or 1.0


class _Writer:
    def __init__(self, urdf: Urdf, sites: list[SiteSpec]) -> None:
        self.urdf, self.m = urdf, urdf.model
        self.sites = {
            b: [s for s in sites if body_of_link(urdf, s.link) == b] for b in range(self.m.nbody)
        }
        self.lines: list[str] = []

    def body(self, b: int, depth: int) -> None:
        m, pad = self.m, "  " * depth
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
        frame = ""
        if np.any(m.body_pos[b]):
            frame += f' pos="{exact(m.body_pos[b])}"'
        if not np.array_equal(m.body_quat[b], [1.0, 0.0, 0.0, 0.0]):
            frame += f' quat="{exact(m.body_quat[b])}"'
        self.lines.append(f'{pad}<body name="{name}"{frame}>')
        inner = pad + "  "
        if name in self.urdf.with_inertial:
            self.lines.append(
                f'{inner}<inertial pos="{exact(m.body_ipos[b])}" quat="{exact(m.body_iquat[b])}" '
                f'mass="{exact(m.body_mass[b])}" diaginertia="{exact(m.body_inertia[b])}"/>'
            )
        for j in range(m.njnt):
            if m.jnt_bodyid[j] != b:
                continue
            kind = "hinge" if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE) else "slide"
            attrs = f'name="{mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)}" type="{kind}"'
            attrs += f' axis="{exact(m.jnt_axis[j])}"'
            if np.any(m.jnt_pos[j]):
                attrs += f' pos="{exact(m.jnt_pos[j])}"'
            if m.jnt_limited[j]:
                attrs += f' range="{exact(m.jnt_range[j])}"'
            self.lines.append(f"{inner}<joint {attrs}/>")
        children = [c for c in range(1, m.nbody) if m.body_parentid[c] == b]
        for c in children:
            if np.linalg.norm(m.body_pos[c]) > 1e-9:
                self.lines.append(f'{inner}<geom fromto="0 0 0 {exact(m.body_pos[c])}"/>')
        for s in self.sites[b]:
            frame = f' pos="{exact(s.pos)}"' if any(s.pos) else ""
            if s.quat != (1.0, 0.0, 0.0, 0.0):
                frame += f' quat="{exact(s.quat)}"'
            colour = "1 0.2 0.2 1" if s.name == "tool" else "0.1 0.8 0.2 1"
            self.lines.append(f'{inner}<site name="{s.name}"{frame} rgba="{colour}"/>')
        for c in children:
            self.body(c, depth + 1)
        self.lines.append(f"{pad}</body>")


def build_xml(urdf: Urdf, name: str, sites: list[SiteSpec]) -> str:
    """The MJCF text of the URDF's kinematic tree with actuators, sites and home."""
    m = urdf.model
    reach = _reach(m)
    w = _Writer(urdf, sites)
    w.lines += [
        f"<!-- {name}: from the URDF {urdf.path.name} (robot '{urdf.name}'), generated by",
        "     pkm-calib from-urdf; regenerate it rather than edit it.",
        "     Units: metres and radians. Every link is a body (fixed joints too); actuators are",
        "     the movable joints, named after them. Capsules between joint origins are for",
        "     viewing only (the URDF's meshes are left out)."
        + ("" if urdf.with_inertial else " No inertia: kinematics only.")
        + " -->",
        f'<mujoco model="{name}">',
        '  <compiler angle="radian" autolimits="true"/>',
        '  <option><flag contact="disable"/></option>',
        "  <default>",
        f'    <geom type="capsule" size="{exact(0.02 * reach)}" density="0" contype="0" '
        'conaffinity="0" group="1" rgba="0.6 0.62 0.66 1"/>',
        f'    <site size="{exact(0.006 * reach)}"/>',
        "  </default>",
        "  <worldbody>",
    ]
    for b in range(1, m.nbody):
        if m.body_parentid[b] == 0:
            w.body(b, 2)
    w.lines += ["  </worldbody>", "  <actuator>"]
    home = []
    for j in range(m.njnt):
        joint = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
        limit = f' ctrlrange="{exact(m.jnt_range[j])}"' if m.jnt_limited[j] else ""
        w.lines.append(f'    <position name="{joint}" joint="{joint}" kp="{KP:g}"{limit}/>')
        home.append(_home(m, j))
    w.lines += ["  </actuator>", "  <keyframe>", f'    <key name="home" qpos="{exact(home)}"/>']
    w.lines += ["  </keyframe>", "</mujoco>", ""]
    return "\n".join(w.lines)


def _check_joints(m: mujoco.MjModel, path: Path) -> None:
    for j in range(m.njnt):
        if int(m.jnt_type[j]) not in (
            int(mujoco.mjtJoint.mjJNT_HINGE),
            int(mujoco.mjtJoint.mjJNT_SLIDE),
        ):
            raise UrdfError(f"{path}: MuJoCo made joint {j} neither a hinge nor a slide")


def convert(
    urdf_path: str | Path, targets: list[str], tool: str | None, name: str | None
) -> tuple[str, str, Mechanism]:
    """(MJCF text, error-model text, the Mechanism of the text) of a URDF."""
    if not targets:
        raise UrdfError("give at least one reflector: --target target_1=LINK[@x,y,z]")
    specs = [parse_site(t, "--target", named=True) for t in targets]
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise UrdfError(f"--target names must differ, got {names}")
    tool_spec = (
        parse_site(tool, "--tool", named=False)
        if tool
        else SiteSpec("tool", specs[0].link, (0.0, 0.0, 0.0))
    )
    urdf = read_urdf(urdf_path)
    _check_joints(urdf.model, urdf.path)
    for s in [*specs, tool_spec]:
        body_of_link(urdf, s.link)
    name = name or urdf.name
    if not _NAME.match(name):
        raise UrdfError(
            f"model name '{name}' is not a valid name (letters, digits, _ . -); give --name"
        )
    xml = build_xml(urdf, name, [tool_spec, *specs])
    mech = Mechanism.from_xml_string(xml)
    return xml, error_model_toml(mech, f"{name}.xml"), mech


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="pkm-calib from-urdf", description=__doc__.split("\n")[0])
    ap.add_argument("urdf", help="the robot's URDF")
    ap.add_argument(
        "--target",
        action="append",
        default=[],
        help="a reflector: target_<id>=LINK[@x,y,z] (mm, in the link's frame); repeat for more",
    )
    ap.add_argument("--tool", help="the commanded frame: LINK[@x,y,z[,rx,ry,rz]] (mm, deg)")
    ap.add_argument("--name", help="the model's name (default: the robot's)")
    ap.add_argument("--out-dir", required=True, help="where to write NAME.xml and NAME.params.toml")
    ap.add_argument(
        "--force", action="store_true", help="replace existing NAME.xml, NAME.params.toml"
    )
    args = ap.parse_args(argv)
    try:
        xml, toml, mech = convert(args.urdf, args.target, args.tool, args.name)
        names = [f"{mech.name}.xml", f"{mech.name}.params.toml"]
        model_file, errors_file = out_files(args.out_dir, names, args.force)
    except TwinError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RecursionError:
        print(f"error: {args.urdf}: its tree of links is too deep to convert", file=sys.stderr)
        return 2
    if not write_model_files({model_file: xml, errors_file: toml}):  # both, or neither
        return 2
    print(
        f"wrote {model_file} ({mech.n_actuators} actuators {list(mech.actuator_names)}, "
        f"{mech.n_targets} reflector(s)) and {errors_file} ({toml.count('[[parameter]]')} "
        f"parameters); datasets of this machine name the model '{mech.name}' (--name sets it)"
    )
    return 0


from_urdf_command = main  # pkm-calib from-urdf (pkm_calib.command)

if __name__ == "__main__":
    raise SystemExit(main())
