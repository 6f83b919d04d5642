"""A URDF compiled by MuJoCo, for kinematics: its links as bodies, its joints, its inertials.

MuJoCo reads URDF itself. Before it does, the file is checked for what a machine model here
can hold (a tree of revolute, continuous, prismatic and fixed joints; no mimic, floating or
planar joint) and its ``<visual>`` and ``<collision>`` elements are left out: kinematics does
not need them, and their meshes (often ``package://`` paths) would stop the compile. Fixed
joints are kept as bodies (MuJoCo's ``fusestatic`` is turned off for URDF), so that every
link a user names exists. Links without an ``<inertial>`` get MuJoCo's bounded defaults.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco

from twin.exceptions import ModelError
from twin.formats.parameter_file import read_utf8
from twin.mechanism import compile_spec

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed")


class UrdfError(ModelError):
    """A URDF that cannot be used (the message names the file and the element)."""


@dataclass(frozen=True)
class Urdf:
    """A URDF compiled by MuJoCo."""

    path: Path
    name: str  # the robot's name
    model: mujoco.MjModel
    links: tuple[str, ...]  # in the file's order
    joints: tuple[str, ...]  # the movable ones, in the file's order
    with_inertial: frozenset[str]  # links that declare an <inertial>
    masses_defaulted: bool


def _kinematic_text(root: ET.Element) -> str:
    for link in root.iter("link"):
        for child in list(link):
            if child.tag in ("visual", "collision"):
                link.remove(child)
    return ET.tostring(root, encoding="unicode")


def read_urdf(path: str | Path) -> Urdf:
    """Check and compile a URDF file (errors name the file and the element)."""
    path = Path(path)
    if not path.is_file():
        raise UrdfError(f"URDF file not found: {path}")
    try:
        root = ET.fromstring(read_utf8(path))
    except (UnicodeError, ET.ParseError) as exc:
        raise UrdfError(f"{path} is not readable XML: {exc}") from None
    if root.tag != "robot":
        raise UrdfError(f"{path} is not a URDF: its root element is <{root.tag}>, not <robot>")
    name = root.get("name", "").strip()
    if not name:
        raise UrdfError(f"{path}: <robot> has no name")
    links = tuple(link.get("name", "") for link in root.findall("link"))
    if not links or not all(links):
        raise UrdfError(f"{path}: every <link> needs a name, and a robot at least one link")
    movable = []
    for joint in root.findall("joint"):
        jname, kind = joint.get("name", ""), joint.get("type", "")
        if kind not in JOINT_TYPES:
            raise UrdfError(
                f"{path}: joint '{jname}' is of type '{kind}'; a machine model here takes "
                f"{list(JOINT_TYPES)}"
            )
        if joint.find("mimic") is not None:
            raise UrdfError(
                f"{path}: joint '{jname}' mimics another joint; give it its own actuator "
                "instead (a mimic joint is not supported)"
            )
        if kind != "fixed":
            movable.append(jname)
    if not movable:
        raise UrdfError(f"{path}: no movable joint: nothing to command")
    with_inertial = frozenset(
        link.get("name", "") for link in root.findall("link") if link.find("inertial") is not None
    )
    try:
        spec = mujoco.MjSpec.from_string(_kinematic_text(root))
    except ValueError as exc:
        raise UrdfError(f"MuJoCo could not read {path}: {exc}") from None
    spec.compiler.fusestatic = False
    spec.modelfiledir = str(path.parent)
    model, defaulted = compile_spec(spec, str(path))
    return Urdf(path, name, model, links, tuple(movable), with_inertial, defaulted)


def body_of_link(urdf: Urdf, link: str) -> int:
    """The body id of ``link``; the error names the URDF and the closest link."""
    from twin.formats.parameter_file import closest

    b = mujoco.mj_name2id(urdf.model, mujoco.mjtObj.mjOBJ_BODY, link)
    if b < 0:
        raise UrdfError(
            f"{urdf.path} has no link '{link}'{closest(link, urdf.links)}; its links are "
            f"{list(urdf.links)}"
        )
    return int(b)
