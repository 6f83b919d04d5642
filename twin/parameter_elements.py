"""Where a parameter's element is in a MuJoCo model: its id, and an actuator's joint."""

from __future__ import annotations

import difflib
from typing import Any

import mujoco

from twin.exceptions import ParameterError

HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)


def _names(model: mujoco.MjModel, obj: mujoco.mjtObj, count: int) -> list[str]:
    return [n for n in (mujoco.mj_id2name(model, obj, i) for i in range(count)) if n]


def element_id(model: mujoco.MjModel, p: Any) -> int:
    """The id of ``p``'s element; a clear error (with the closest name) if there is none."""
    obj, count = {
        "body_pos": (mujoco.mjtObj.mjOBJ_BODY, model.nbody),
        "body_rot": (mujoco.mjtObj.mjOBJ_BODY, model.nbody),
        "site_pos": (mujoco.mjtObj.mjOBJ_SITE, model.nsite),
        "joint_zero": (mujoco.mjtObj.mjOBJ_JOINT, model.njnt),
    }.get(p.kind, (mujoco.mjtObj.mjOBJ_ACTUATOR, model.nu))  # the actuation kinds
    i = mujoco.mj_name2id(model, obj, p.element)
    if i < 0:
        what = obj.name[6:].lower()
        near = difflib.get_close_matches(p.element, _names(model, obj, count), n=1)
        hint = f" (did you mean '{near[0]}'?)" if near else ""
        raise ParameterError(
            f"parameter '{p.name}': the model has no {what} named '{p.element}'{hint}"
        )
    return int(i)


def actuated_joint(model: mujoco.MjModel, p: Any, actuator: int) -> int:
    """The slide or hinge joint that actuator ``actuator`` drives (a gain scales its travel,
    a compliance yields it)."""
    j = int(model.actuator_trnid[actuator, 0])
    if int(model.actuator_trntype[actuator]) != int(mujoco.mjtTrn.mjTRN_JOINT) or int(
        model.jnt_type[j]
    ) not in (HINGE, SLIDE):
        raise ParameterError(
            f"parameter '{p.name}': actuator '{p.element}' does not drive a slide or hinge "
            f"joint, so it has no {p.kind}"
        )
    return j
