"""A 6-DoF probe (a T-Mac, a T-Probe): the tracker reads the frame of a target, not only its
point, with an orientation noise of its own.

The probe's true frame is the truth's target site frame at the machine's true pose: the tool
rotation the measurement found (twin.measurement.Measurement.true_rotation) times the site's fixed
rotation relative to the tool site (the probe sits on the tool's body). The reading is that
rotation in the reading's frame (the tracker's own, or the base), turned by a noise rotation
``Exp(n)`` with ``n`` gaussian of ``sigma_rad`` per axis, for every repeat.
"""

from __future__ import annotations

import mujoco
import numpy as np

from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rotvec, quat_from_matrix
from twin.tracker import Tracker


def _site_frames(mech: Mechanism, qpos: np.ndarray, sites: list[int]) -> np.ndarray:
    data = mujoco.MjData(mech.model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(mech.model, data)
    return np.array([data.site_xmat[s].reshape(3, 3) for s in sites])


def tool_to_target(mech: Mechanism) -> np.ndarray:
    """(T, 3, 3): each target site's rotation relative to the tool site; raises for a target
    that does not sit on the tool's body (its orientation would not follow the tool's)."""
    body = mech.model.site_bodyid
    off = [
        n
        for n, s in zip(mech.target_names, mech.target_sites, strict=True)
        if body[s] != body[mech.tool_site]
    ]
    if off:
        raise ValueError(f"a probe must sit on the tool's body; {off} do not")
    frames = _site_frames(mech, mech.home_qpos, [mech.tool_site, *mech.target_sites])
    return np.einsum("ji,tjk->tik", frames[0], frames[1:])


def probe_orientations(
    truth: Mechanism,
    true_tool_rotation: np.ndarray,
    tracker: Tracker | None,
    sigma_rad: float,
    repeats: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """Unit quaternions (P, T, R, 4) of every target's frame at the tool rotations (P, 3, 3),
    in the tracker's frame (``tracker``) or the base's (None), with orientation noise."""
    rel = tool_to_target(truth)
    rot = np.einsum("pij,tjk->ptik", np.asarray(true_tool_rotation, dtype=float), rel)
    if tracker is not None:
        r_bt, _ = tracker.base_from_tracker
        rot = np.einsum("ji,ptjk->ptik", r_bt, rot)
    p, t = rot.shape[:2]
    noise = matrix_from_rotvec(rng.standard_normal((p, t, repeats, 3)) * sigma_rad)
    return quat_from_matrix(noise @ rot[:, :, None])
