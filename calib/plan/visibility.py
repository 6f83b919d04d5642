"""Can the tracker see each reflector? Line of sight by ray casting, and the incidence angle.

A reflector is visible when the ray from the tracker head to the target site hits no geom
before it, or only a geom of the target's own body (its mount: the reflector sits on that
surface), and when the angle between the reflector's normal and the direction to the tracker
is within the acceptance angle (about 30 deg for a spherically mounted retroreflector). The
reflector's normal is taken as the target site's z axis (an assumption: MJCF sites carry no
normal; orient the site so that its z axis points out of the reflector's opening)."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from twin.mechanism import Mechanism

HIT_BEFORE = 1.0 - 1e-9  # a hit at a fraction of the way below this lies before the target


def occluded_by(m: mujoco.MjModel, d: mujoco.MjData, tracker: np.ndarray, site: int) -> int | None:
    """The body blocking the line of sight to ``site`` (at the last kinematics), or None."""
    target = d.site_xpos[site]
    vec = target - tracker
    geom = np.array([-1], dtype=np.int32)
    x = mujoco.mj_ray(m, d, tracker, vec, None, 1, -1, geom)
    if x < 0 or x >= HIT_BEFORE or geom[0] < 0:
        return None
    body = int(m.geom_bodyid[geom[0]])
    return None if body == int(m.site_bodyid[site]) else body


def incidence_deg(d: mujoco.MjData, tracker: np.ndarray, site: int) -> float:
    """Angle (deg) between the site's z axis and the direction from the site to the tracker."""
    normal = d.site_xmat[site].reshape(3, 3)[:, 2]
    to_tracker = tracker - d.site_xpos[site]
    cos = float(normal @ to_tracker) / max(float(np.linalg.norm(to_tracker)), 1e-300)
    return math.degrees(math.acos(max(-1.0, min(1.0, cos))))


def visibility_problem(
    mech: Mechanism,
    m: mujoco.MjModel,
    d: mujoco.MjData,
    tracker: np.ndarray,
    acceptance_deg: float,
) -> str | None:
    """Why some target is not seen at the configuration last computed in ``d``, or None."""
    for name, site in zip(mech.target_names, mech.target_sites, strict=True):
        body = occluded_by(m, d, tracker, int(site))
        if body is not None:
            blocker = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body) or str(body)
            return f"{name} hidden from the tracker by body '{blocker}'"
        angle = incidence_deg(d, tracker, int(site))
        if angle > acceptance_deg:
            return f"{name} faces {angle:.0f} deg away from the tracker (> {acceptance_deg:g})"
    return None
