"""Backlash / lost motion: the actuator stops short by half the play in the approach direction.

The k-th pose in measurement order is approached from the previous one: an actuator that moved
up stops ``play/2`` below its command, one that moved down ``play/2`` above it (the first pose
is approached from the home configuration).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.mechanism import Mechanism


@dataclass(frozen=True)
class Backlash:
    play_m: float = 10e-6  # prismatic actuators
    play_rad: float = 0.0  # revolute actuators
    name: str = "backlash"

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        seq = np.argsort(order, kind="stable")
        home = mech.home_qpos[mech.actuator_qpos]
        previous = np.vstack([home, commands[seq][:-1]])
        direction = np.sign(commands[seq] - previous)
        play = np.where(mech.actuator_is_slide, self.play_m, self.play_rad)
        out = commands.copy()
        out[seq] = commands[seq] - 0.5 * play[None, :] * direction
        return out
