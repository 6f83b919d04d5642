"""Pinocchio as a second, independent kinematics engine for an MJCF model.

MuJoCo computes every pose and Jacobian the twin and calib use; pinocchio reads the same
MJCF with its own parser and its own algorithms, so agreement between the two checks both
the model file and the code that drives MuJoCo.

Pinocchio's MJCF parser differs from MuJoCo's compiler in ways that this module absorbs by
rewriting the MJCF into a pinocchio-only file (MuJoCo would refuse it):

* it reads only the first ``<body>`` under ``<worldbody>``: the whole world content is wrapped
  in a static root body, and inside it a static body that carries the world-level sites
  (pinocchio drops the sites of its root body, but keeps those of static child bodies);
* a body and a site with the same name make the constraint import ambiguous (it looks frames
  up by name only): such bodies are renamed with :data:`BODY_SUFFIX`;
* joint ``ref`` is folded into the joint placement for a body with one joint but not for the
  first joint of a body with several (a composite joint) in pinocchio 4.1: every ``ref`` is
  removed, so pinocchio's zero of a hinge or slide joint is the pose written in the file, and
  its coordinate is MuJoCo's kinematic displacement ``qpos - qpos0``;
* keyframes are removed (their values would follow MuJoCo's convention): map configurations
  with :func:`qpos_mujoco_to_pinocchio`.

Coordinates: MuJoCo quaternions are ``w, x, y, z``, pinocchio's ``x, y, z, w`` (free joint:
position then quaternion in both). Velocities: a MuJoCo free joint has the linear velocity of
the body origin in the world frame and the angular velocity in the body frame; a pinocchio
free flyer has both in the body frame, so ``v_pin = T v_mj`` with ``T = diag(R^T, I)`` on
that joint (:func:`velocity_map`); hinge, slide and ball coordinates agree.
"""

from __future__ import annotations

import importlib
import os
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from twin.exceptions import ModelError
from twin.rotations import matrix_from_quat

if TYPE_CHECKING:
    import pinocchio as pin

ROOT_BODY = "pinocchio_root"  # static root body wrapping the world (its sites are dropped)
WORLD_BODY = "pinocchio_world"  # static body carrying the world-level sites and bodies


def _pinocchio():
    """pinocchio, imported when a cross-check asks for it: it is a test tool (the dev extra,
    package ``pin``), not a dependency of the calibration commands."""
    try:
        return importlib.import_module("pinocchio")
    except ImportError:
        raise ModelError(
            "the pinocchio cross-check needs pinocchio: pip install 'pkm-calib[dev]'"
        ) from None


BODY_SUFFIX = "__body"  # appended to a body whose name is also a site's name
COMPOSITE_PREFIX = "Composite_"  # pinocchio's name for the joints of a multi-joint body

FREE = int(mujoco.mjtJoint.mjJNT_FREE)
BALL = int(mujoco.mjtJoint.mjJNT_BALL)
_NQ = {FREE: 7, BALL: 4}
_NV = {FREE: 6, BALL: 3}


# --------------------------------------------------------------------------- model loading
def pinocchio_mjcf_string(path: str | Path) -> str:
    """The MJCF at ``path`` rewritten for pinocchio's parser (see the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"MJCF file not found: {path}")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ModelError(f"{path} is not well-formed XML: {exc}") from exc
    if root.tag != "mujoco":
        raise ModelError(f"{path}: the root element is <{root.tag}>, not <mujoco>")
    if root.find(".//include") is not None:
        raise ModelError(f"{path}: <include> is not supported by the pinocchio cross-check")
    worldbody = root.find("worldbody")
    if worldbody is None:
        raise ModelError(f"{path} has no <worldbody>")

    bodies = list(worldbody.iter("body"))
    body_names = {b.get("name") for b in bodies}
    for taken in (ROOT_BODY, WORLD_BODY):
        if taken in body_names:
            raise ModelError(f"{path}: the body name '{taken}' is reserved for the cross-check")
    site_names = {s.get("name") for s in worldbody.iter("site") if s.get("name")}
    renamed = {}
    for body in bodies:
        name = body.get("name")
        if name in site_names:
            new = name + BODY_SUFFIX
            if new in body_names:
                raise ModelError(f"{path}: cannot rename body '{name}': '{new}' exists")
            body.set("name", new)
            renamed[name] = new
    for eq in root.iter("equality"):
        for constraint in eq:
            for key in ("body1", "body2"):
                if constraint.get(key) in renamed:
                    constraint.set(key, renamed[constraint.get(key)])

    for joint in root.iter("joint"):
        joint.attrib.pop("ref", None)
    for keyframe in root.findall("keyframe"):
        root.remove(keyframe)
    compiler = root.find("compiler")
    if compiler is None:
        compiler = ET.Element("compiler")
        root.insert(0, compiler)
    compiler.set("autolimits", compiler.get("autolimits", "true"))
    if not root.get("model"):
        root.set("model", path.stem)

    children = list(worldbody)
    wrapper = ET.Element("body", {"name": ROOT_BODY})
    world = ET.SubElement(wrapper, "body", {"name": WORLD_BODY})
    for child in children:
        worldbody.remove(child)
        world.append(child)
    worldbody.append(wrapper)
    return ET.tostring(root, encoding="unicode")


def pinocchio_from_mjcf(
    path: str | Path, constraints: bool = True
) -> tuple[pin.Model, list | None]:
    """Pinocchio model of the MJCF at ``path`` and its closure constraints.

    The constraints are pinocchio's import of the site-based ``weld`` (FrameAnchor) and
    ``connect`` (PointAnchor) equalities, points first; ``None`` when not asked for or when
    this pinocchio has no ``buildModelAndConstraintsFromMJCF``.
    """
    pin = _pinocchio()
    xml = pinocchio_mjcf_string(path)
    fd, tmp = tempfile.mkstemp(suffix=".xml", prefix="pinocchio_")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(xml)
        try:
            if constraints and hasattr(pin, "buildModelAndConstraintsFromMJCF"):
                model, points, frames = pin.buildModelAndConstraintsFromMJCF(tmp)
                return model, [*points, *frames]
            return pin.buildModelFromMJCF(tmp), None
        except (RuntimeError, ValueError) as exc:
            raise ModelError(f"pinocchio could not read {path}: {exc}") from exc
    finally:
        os.unlink(tmp)


# --------------------------------------------------------------------------- coordinates
@dataclass(frozen=True)
class JointMatch:
    """One MuJoCo joint and the pinocchio (sub-)joint that moves the same body."""

    name: str
    kind: int  # mjtJoint
    mj_qpos: int  # first qpos address in MuJoCo
    mj_dof: int  # first dof address in MuJoCo
    pin_q: int  # first configuration index in pinocchio
    pin_v: int  # first velocity index in pinocchio


def match_joints(model_mj: mujoco.MjModel, model_pin: pin.Model) -> tuple[JointMatch, ...]:
    """Pair every MuJoCo joint with its pinocchio (sub-)joint, by joint name."""
    matches = []
    for jid in range(1, model_pin.njoints):
        pin_name = model_pin.names[jid]
        jmodel = model_pin.joints[jid]
        if jmodel.shortname() == "JointModelComposite":
            subs = list(jmodel.extract().joints)
            first = _mj_joint(model_mj, pin_name.removeprefix(COMPOSITE_PREFIX), pin_name)
            body = int(model_mj.jnt_bodyid[first])
            mj_ids = range(model_mj.body_jntadr[body], model_mj.body_jntadr[body] + len(subs))
            if first != model_mj.body_jntadr[body] or model_mj.body_jntnum[body] != len(subs):
                raise ModelError(
                    f"pinocchio joint '{pin_name}' has {len(subs)} sub-joints; MuJoCo body "
                    f"{body} has {model_mj.body_jntnum[body]} joints"
                )
        else:
            subs = [jmodel]
            mj_ids = [_mj_joint(model_mj, pin_name, pin_name)]
        for sub, j in zip(subs, mj_ids, strict=True):
            kind = int(model_mj.jnt_type[j])
            if sub.nq != _NQ.get(kind, 1) or sub.nv != _NV.get(kind, 1):
                raise ModelError(
                    f"joint '{model_mj.joint(j).name}': pinocchio {sub.shortname()} "
                    f"(nq {sub.nq}, nv {sub.nv}) does not match MuJoCo joint type {kind}"
                )
            matches.append(
                JointMatch(
                    model_mj.joint(j).name,
                    kind,
                    int(model_mj.jnt_qposadr[j]),
                    int(model_mj.jnt_dofadr[j]),
                    int(sub.idx_q),
                    int(sub.idx_v),
                )
            )
    if len(matches) != model_mj.njnt:
        raise ModelError(
            f"pinocchio has {len(matches)} joints, MuJoCo {model_mj.njnt}: the models differ"
        )
    return tuple(matches)


def _mj_joint(model_mj: mujoco.MjModel, name: str, pin_name: str) -> int:
    j = mujoco.mj_name2id(model_mj, mujoco.mjtObj.mjOBJ_JOINT, name)
    if j < 0:
        raise ModelError(
            f"pinocchio joint '{pin_name}' has no MuJoCo joint '{name}' (name every joint)"
        )
    return int(j)


def qpos_mujoco_to_pinocchio(
    model_mj: mujoco.MjModel, model_pin: pin.Model, qpos: np.ndarray
) -> np.ndarray:
    """Pinocchio configuration ``q`` equal to MuJoCo's ``qpos`` (same joint, same pose).

    Hinge and slide: ``qpos - qpos0`` (pinocchio's zero is the pose in the file, MuJoCo's is
    ``qpos0`` = ``ref``, or an injected encoder offset); ball and free: quaternion reordered
    from ``w, x, y, z`` to ``x, y, z, w``.
    """
    qpos = np.asarray(qpos, dtype=float)
    if qpos.shape != (model_mj.nq,):
        raise ValueError(f"qpos must have shape ({model_mj.nq},), got {qpos.shape}")
    q = np.zeros(model_pin.nq)
    for m in match_joints(model_mj, model_pin):
        a, b = m.mj_qpos, m.pin_q
        if m.kind == FREE:
            q[b : b + 3] = qpos[a : a + 3]
            q[b + 3 : b + 7] = _xyzw(qpos[a + 3 : a + 7])
        elif m.kind == BALL:
            q[b : b + 4] = _xyzw(qpos[a : a + 4])
        else:
            q[b] = qpos[a] - model_mj.qpos0[a]
    return q


def _xyzw(wxyz: np.ndarray) -> np.ndarray:
    return np.array([wxyz[1], wxyz[2], wxyz[3], wxyz[0]])


def velocity_map(model_mj: mujoco.MjModel, model_pin: pin.Model, qpos: np.ndarray) -> np.ndarray:
    """``T`` (nv_pin, nv_mj) with ``v_pin = T v_mj`` at MuJoCo configuration ``qpos``.

    A Jacobian with respect to MuJoCo's velocities follows as ``J_mj = J_pin T``.
    """
    qpos = np.asarray(qpos, dtype=float)
    t = np.zeros((model_pin.nv, model_mj.nv))
    for m in match_joints(model_mj, model_pin):
        a, b = m.mj_dof, m.pin_v
        n = _NV.get(m.kind, 1)
        t[b : b + n, a : a + n] = np.eye(n)
        if m.kind == FREE:
            # MuJoCo: origin velocity in the parent (world) frame; pinocchio: in the body frame.
            r = matrix_from_quat(qpos[m.mj_qpos + 3 : m.mj_qpos + 7])
            t[b : b + 3, a : a + 3] = r.T
    return t


# --------------------------------------------------------------------------- frames
def site_frame_id(model_pin: pin.Model, site_name: str) -> int:
    """Pinocchio frame index of an MJCF site (an OP_FRAME of the same name)."""
    pin = _pinocchio()
    if not model_pin.existFrame(site_name, pin.FrameType.OP_FRAME):
        raise ModelError(f"pinocchio model '{model_pin.name}' has no site frame '{site_name}'")
    return int(model_pin.getFrameId(site_name, pin.FrameType.OP_FRAME))


def frame_placement(
    model_pin: pin.Model, data_pin: pin.Data, q: np.ndarray, site_name: str
) -> tuple[np.ndarray, np.ndarray]:
    """World rotation (3, 3) and position (3,) of a site at pinocchio configuration ``q``."""
    fid, pin = site_frame_id(model_pin, site_name), _pinocchio()
    pin.framesForwardKinematics(model_pin, data_pin, np.asarray(q, dtype=float))
    placement = data_pin.oMf[fid]
    return placement.rotation.copy(), placement.translation.copy()


def frame_jacobian_world(
    model_pin: pin.Model, data_pin: pin.Data, q: np.ndarray, site_name: str
) -> np.ndarray:
    """Site Jacobian (6, nv) in LOCAL_WORLD_ALIGNED: rows are the site origin's linear velocity
    then the angular velocity, both in world axes (MuJoCo's ``mj_jacSite`` convention)."""
    fid, pin = site_frame_id(model_pin, site_name), _pinocchio()
    return pin.computeFrameJacobian(
        model_pin,
        data_pin,
        np.asarray(q, dtype=float),
        fid,
        pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
    ).copy()
