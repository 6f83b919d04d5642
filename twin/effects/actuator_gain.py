"""Actuator gain (scale) error: each joint travels (1 + g_i) times its commanded travel.

joint = q0 + (command - q0) (1 + g_i), with q0 the joint's zero (where its encoder is
referenced; 0 for the revolute joints of a serial arm, so joint = command (1 + g_i)). Causes:
a screw's lead off its nominal (a C7 screw is +-52 um per 300 mm, 170 ppm), an encoder
scale or a linear scale's graduation (a steel scale read at 23 C instead of 20 C: 35 ppm),
an output encoder's grating. 100-500 ppm per actuator is the range of uncalibrated drives;
the default draws each g_i uniformly within +-200 ppm (seeded) unless ``gains_ppm`` gives them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twin.effects._checks import finite, floats, seed
from twin.exceptions import ModelError
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class ActuatorGain:
    gains_ppm: tuple[float, ...] = field(default=())  # one per actuator; () draws them
    magnitude_ppm: float = 200.0  # bound of the drawn gains
    seed: int = 0
    name: str = "actuator_gain"

    def __post_init__(self) -> None:
        object.__setattr__(self, "gains_ppm", floats(self.gains_ppm, "gains_ppm"))
        finite(self.magnitude_ppm, "magnitude_ppm", min=0.0)
        seed(self.seed)

    def gains(self, mech: Mechanism) -> np.ndarray:
        """g_i (A,), dimensionless."""
        n = mech.n_actuators
        if not self.gains_ppm:
            rng = np.random.default_rng(self.seed)
            return 1e-6 * self.magnitude_ppm * rng.uniform(-1.0, 1.0, n)
        if len(self.gains_ppm) != n:
            raise ModelError(
                f"actuator_gain needs {n} gains for {mech.actuator_names}, "
                f"got {len(self.gains_ppm)}"
            )
        return 1e-6 * np.asarray(self.gains_ppm)

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        g = self.gains(mech)[None, :]
        zero = mech.model.qpos0[mech.actuator_qpos][None, :]
        return np.where(g != 0.0, zero + (commands - zero) * (1.0 + g), commands)
