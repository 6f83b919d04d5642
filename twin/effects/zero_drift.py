"""Zero drift: where an actuator's position measurement reads zero moves after switch-on.

A linear scale or a rotary encoder is fixed to a structure that warms with its drive; the
read head moves against the graduation, so the joint stands off its command by an offset that
grows in time and settles:

    q = c + r_a h(t),   h(t) = tau_s (1 - exp(-t / tau_s)),   t = start_s + k seconds_per_pose

for the k-th pose in measurement order, ``r_a`` the initial rate of actuator a (metres or
radians per second: ``rates``, one per actuator). Magnitudes: a scale's mount moving a few
micrometres over the first hour (1e-9 m/s initially with a 30 min time constant: 1.1 um).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.effects._checks import finite, floats
from twin.exceptions import ModelError
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class ZeroDrift:
    rates: tuple[float, ...] = ()  # initial drift rate per actuator (m/s or rad/s)
    tau_s: float = 1800.0  # time constant of the settling
    seconds_per_pose: float = 30.0
    start_s: float = 0.0
    name: str = "zero_drift"

    def __post_init__(self) -> None:
        object.__setattr__(self, "rates", floats(self.rates, "rates"))
        finite(self.tau_s, "tau_s", above=0.0)
        finite(self.seconds_per_pose, "seconds_per_pose", min=0.0)
        finite(self.start_s, "start_s", min=0.0)

    def offset(self, k: np.ndarray) -> np.ndarray:
        """h(t) at the k-th poses (N,): the drift per unit initial rate, seconds."""
        t = self.start_s + self.seconds_per_pose * np.asarray(k, dtype=float)
        return self.tau_s * -np.expm1(-t / self.tau_s)

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        if len(self.rates) != mech.n_actuators:
            raise ModelError(
                f"zero_drift needs one rate per actuator of {mech.actuator_names}, got "
                f"{len(self.rates)}"
            )
        return commands + self.offset(order)[:, None] * np.asarray(self.rates)[None, :]
