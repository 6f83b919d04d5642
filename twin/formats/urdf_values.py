"""A URDF with a model's geometry written into its joint origins: the calibrated URDF.

For a model generated from a URDF (twin.formats.from_urdf: every link a body of the same name,
every joint a joint of the same name at its child body's origin), ``urdf_with_model`` returns
the URDF's text with each joint's ``<origin xyz rpy>`` set to the child body's placement in
the given model (with its errors injected) and a movable joint's zero folded in: MuJoCo turns
a joint by ``qpos - qpos0`` from its body's placement, a URDF by ``q`` from the joint's
origin, so the origin is turned about the joint's axis by ``-qpos0`` (a hinge) or moved along
it by ``-qpos0`` (a slide). The joint values are then the model's. A placement of the root
link (a base error) goes into a fixed joint from a new root link ``calibrated_base``.

Everything else (links, visuals, inertials, limits, comments) is kept; rpy are written with
every digit (``R = Rz(yaw) Ry(pitch) Rx(roll)``, a pitch of +-90 deg handled). A URDF has no
sites, no actuators and no joint scales: reflector and tool offsets, actuator gains and the
like cannot be written into it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

from twin.formats.mjcf_values import exact
from twin.formats.parameter_file import read_utf8
from twin.formats.urdf_import import UrdfError
from twin.rotations import matrix_from_quat, quat_from_rotvec, quat_multiply

NEW_ROOT = "calibrated_base"
_NEAR_LOCK = 1e-12  # cos(pitch) below which roll and yaw are one angle


def rpy_of(r: np.ndarray) -> np.ndarray:
    """(roll, pitch, yaw) of a rotation matrix, ``R = Rz(yaw) Ry(pitch) Rx(roll)``; at a
    pitch of +-90 deg the roll is 0 and the yaw takes the rest."""
    cos_pitch = float(np.hypot(r[0, 0], r[1, 0]))
    pitch = float(np.arctan2(-r[2, 0], cos_pitch))
    if cos_pitch < _NEAR_LOCK:
        return np.array([0.0, pitch, float(np.arctan2(-r[0, 1], r[1, 1]))])
    return np.array(
        [float(np.arctan2(r[2, 1], r[2, 2])), pitch, float(np.arctan2(r[1, 0], r[0, 0]))]
    )


def _placement(model: mujoco.MjModel, b: int) -> tuple[np.ndarray, np.ndarray]:
    """The body's (pos, quat) in its parent with its joint's zero folded in (see above)."""
    pos, quat = model.body_pos[b].copy(), model.body_quat[b].copy()
    for j in range(model.njnt):
        if model.jnt_bodyid[j] != b:
            continue
        if np.any(model.jnt_pos[j]):
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
            raise UrdfError(f"joint '{name}' is not at its body's origin: no URDF joint is so")
        zero = float(model.qpos0[model.jnt_qposadr[j]])
        axis = model.jnt_axis[j]
        if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE):
            quat = quat_multiply(quat, quat_from_rotvec(-zero * axis))
        else:
            pos = pos + matrix_from_quat(quat) @ (-zero * axis)
    return pos, quat


def _set_origin(joint: ET.Element, pos: np.ndarray, quat: np.ndarray) -> None:
    origin = joint.find("origin")
    if origin is None:
        origin = ET.SubElement(joint, "origin")
    origin.set("xyz", exact(pos))
    origin.set("rpy", exact(rpy_of(matrix_from_quat(quat))))


def urdf_with_model(path: str | Path, model: mujoco.MjModel, header: str) -> str:
    """The URDF at ``path`` with the link placements and joint zeros of ``model`` (compiled
    from a model generated from this URDF, errors injected) and ``header`` as a comment."""
    path = Path(path)
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    try:
        root = ET.fromstring(read_utf8(path), parser=parser)
    except (UnicodeError, ET.ParseError) as exc:
        raise UrdfError(f"{path} is not readable XML: {exc}") from None
    children = set()
    for joint in root.findall("joint"):
        child = joint.find("child")
        link = "" if child is None else child.get("link", "")
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, link)
        if b < 0:
            raise UrdfError(f"{path}: joint '{joint.get('name')}' moves link '{link}', "
                            "which the model has no body of")  # fmt: skip
        children.add(link)
        _set_origin(joint, *_placement(model, b))
    roots = [lk.get("name", "") for lk in root.findall("link") if lk.get("name") not in children]
    if len(roots) != 1:
        raise UrdfError(f"{path}: {len(roots)} root links {roots}; a robot has one")
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, roots[0])
    if b < 0:
        raise UrdfError(f"{path}: the model has no body of the root link '{roots[0]}'")
    pos, quat = _placement(model, b)
    if np.any(pos) or not np.array_equal(quat, [1.0, 0.0, 0.0, 0.0]):
        k = list(root).index(root.find("link"))
        base = ET.Element("joint", {"name": f"{NEW_ROOT}_placement", "type": "fixed"})
        ET.SubElement(base, "parent", {"link": NEW_ROOT})
        ET.SubElement(base, "child", {"link": roots[0]})
        _set_origin(base, pos, quat)
        link = ET.Element("link", {"name": NEW_ROOT})
        link.tail = base.tail = "\n  "
        root.insert(k, link)
        root.insert(k + 1, base)
    comment = ET.Comment(" " + header.replace("--", "- -").strip() + " ")
    comment.tail = "\n  "
    root.insert(0, comment)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
