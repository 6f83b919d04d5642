"""Where the targets would be if the machine were its model: the commanded pose carries them."""

from __future__ import annotations

import numpy as np

from twin.kinematics.single_pose import pose_to_frame
from twin.mechanism import Mechanism


def nominal_targets(mech: Mechanism, poses: np.ndarray) -> np.ndarray:
    """Target positions (N, T, 3) at commanded tool poses (N, 6) with the model's gauge."""
    r, p = pose_to_frame(np.atleast_2d(poses))
    local = mech.target_local()
    return np.einsum("nij,tj->nti", r, local) + p[:, None, :]
