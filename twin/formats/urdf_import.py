"""A URDF compiled by MuJoCo, for kinematics: its links as bodies, its joints, its inertials.

MuJoCo reads URDF itself. Before it does, the file is checked for what a machine model here
can hold (a tree of revolute, continuous, prismatic and fixed joints; no mimic, floating or
planar joint) and its ``<visual>`` and ``<collision>`` elements are left out: kinematics does
not need them, and their meshes (often ``package://`` paths) would stop the compile. Fixed
joints are kept as bodies (MuJoCo's ``fusestatic`` is turned off for URDF), so that every
link a user names exists. Links without an ``<inertial>`` get MuJoCo's bounded defaults.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco

from twin.exceptions import ModelError
from twin.formats.parameter_file import read_utf8
from twin.mechanism import compile_spec

JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed")
# the deepest chain of links taken: machines have a few dozen at most, and the MJCF writer
# nests one body per link
MAX_DEPTH = 100
# attributes that hold numbers, checked finite before MuJoCo reads them
NUMBER_ATTRIBUTES = ("xyz", "rpy", "lower", "upper", "value", "ixx", "ixy", "ixz", "iyy")
NUMBER_ATTRIBUTES += ("iyz", "izz", "effort", "velocity")


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
    _check_numbers(root, path)
    _check_limits(root, path)
    _check_depth(root, path)
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


def _where(element: ET.Element, parents: dict[ET.Element, ET.Element]) -> str:
    named = element
    while named is not None and not named.get("name"):
        named = parents.get(named)
    owner = f"{named.tag} '{named.get('name')}'" if named is not None else "the robot"
    return f"<{element.tag}> of {owner}" if named is not element else owner


def _check_numbers(root: ET.Element, path: Path) -> None:
    """Every number a URDF attribute holds is finite (a NaN would reach MuJoCo's compile)."""
    parents = {child: parent for parent in root.iter() for child in parent}
    for element in root.iter():
        for attr in NUMBER_ATTRIBUTES:
            text = element.get(attr)
            if text is None:
                continue
            try:
                values = [float(v) for v in text.split()]
            except ValueError:
                values = []
            if not values or not all(math.isfinite(v) for v in values):
                raise UrdfError(
                    f'{path}: {_where(element, parents)}: {attr}="{text}" is not a list of '
                    "finite numbers"
                )


def _check_limits(root: ET.Element, path: Path) -> None:
    """A prismatic joint has a <limit> (an unlimited slide is no machine's); lower <= upper."""
    for joint in root.findall("joint"):
        name, kind, limit = joint.get("name", ""), joint.get("type", ""), joint.find("limit")
        if kind == "prismatic" and (
            limit is None or limit.get("lower") is None or limit.get("upper") is None
        ):
            raise UrdfError(
                f"{path}: prismatic joint '{name}' has no <limit lower=... upper=...> (m): "
                "give its travel (the URDF standard requires it)"
            )
        if kind in ("revolute", "prismatic") and limit is not None:
            lower, upper = float(limit.get("lower", 0.0)), float(limit.get("upper", 0.0))
            if lower > upper:
                raise UrdfError(
                    f"{path}: joint '{name}' has <limit lower=\"{limit.get('lower')}\" "
                    f'upper="{limit.get("upper")}">: lower is above upper; swap them'
                )


def _check_depth(root: ET.Element, path: Path) -> None:
    """The chain of links is at most MAX_DEPTH deep (counted without recursion)."""
    parent_of = {}
    for joint in root.findall("joint"):
        p, c = joint.find("parent"), joint.find("child")
        if p is not None and c is not None:
            parent_of[c.get("link", "")] = p.get("link", "")
    deepest, depth_of = 0, {}
    for link in parent_of:
        chain, cur = [], link
        while cur in parent_of and cur not in depth_of and len(chain) <= len(parent_of):
            chain.append(cur)
            cur = parent_of[cur]
        base = depth_of.get(cur, 0)
        for i, name in enumerate(reversed(chain)):
            depth_of[name] = base + i + 1
        deepest = max(deepest, depth_of.get(link, 0))
    if deepest > MAX_DEPTH:
        raise UrdfError(
            f"{path}: a chain {deepest} joints deep; a machine model here takes at most {MAX_DEPTH}"
        )


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
