"""Thermal growth of the limbs: length change proportional to a drifting temperature change.

Every prismatic actuator's length L becomes L (1 + alpha dT) with
dT = start_K + rate_K_per_pose * k for the k-th pose in measurement order (a machine warming
up during the sequence). alpha defaults to steel, 11.5e-6 / K.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.mechanism import Mechanism


@dataclass(frozen=True)
class ThermalGrowth:
    start_K: float = 0.0
    rate_K_per_pose: float = 0.02
    alpha_per_K: float = 11.5e-6
    name: str = "thermal_growth"

    def temperature(self, order: np.ndarray) -> np.ndarray:
        return self.start_K + self.rate_K_per_pose * np.asarray(order, dtype=float)

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        grow = 1.0 + self.alpha_per_K * self.temperature(order)[:, None]
        return np.where(mech.actuator_is_slide[None, :], commands * grow, commands)
