"""Compensation: commands that put the identified machine where the user asks.

The identified parameters are injected into the nominal model and its exact closed-chain
inverse kinematics gives the actuator commands for each desired tool pose (the controller
would load the same parameters). The result is re-measured on the real machine (the truth
twin in a scenario) to score it.
"""

from __future__ import annotations

import numpy as np

from calib.model import CalibrationModel
from twin.workspace import commands_for_poses


def compensated_commands(
    model: CalibrationModel, values: np.ndarray, poses: np.ndarray
) -> np.ndarray:
    """Commands (N, A) for desired poses (N, 6) on the model with ``values`` injected."""
    return commands_for_poses(model.mechanism(values), poses)
