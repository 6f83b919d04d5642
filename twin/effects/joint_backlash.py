"""Lost motion of geared joints: the output lags the motor by half the play, by approach.

A revolute joint driven through a gear (harmonic drive, cycloid, planetary) has lost motion:
between the two flanks the output is free by ``play_rad``. Commanded to q after moving up it
stops at q - play/2, after moving down at q + play/2, and a joint that does not move keeps the
side of its last motion (the state persists along the measurement sequence; the first pose is
approached from the home configuration, a joint that never moved sits in the middle).

Magnitudes: harmonic drives specify lost motion below 1 arcmin (CSG/CSF: < 1 arcmin, a few
arcsec of hysteresis loss), cycloid (RV) reducers about 1 arcmin, precision planetaries 1-3
arcmin; an industrial robot joint, measured, 20-60 arcsec. Default 30 arcsec (1.45e-4 rad):
on a 1 m arm about 0.15 mm per joint at the tool. ``play_m`` does the same for prismatic
actuators (ball screw and nut, 0-20 um; the ``backlash`` effect is the memoryless variant).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.effects._checks import finite
from twin.exceptions import ModelError
from twin.mechanism import Mechanism

ARCSEC = math.pi / (180 * 3600)


@dataclass(frozen=True)
class JointBacklash:
    play_rad: float = 30 * ARCSEC  # revolute actuators (30 arcsec)
    play_m: float = 0.0  # prismatic actuators
    name: str = "joint_backlash"

    def __post_init__(self) -> None:
        finite(self.play_rad, "play_rad", min=0.0)
        finite(self.play_m, "play_m", min=0.0)

    def plays(self, mech: Mechanism) -> np.ndarray:
        play = np.where(mech.actuator_is_slide, self.play_m, self.play_rad)
        if not np.any(play) and (self.play_m or self.play_rad):
            missing = "revolute" if self.play_rad else "prismatic"
            given = "play_rad" if self.play_rad else "play_m"
            other = "play_m" if self.play_rad else "play_rad"
            raise ModelError(
                f"joint_backlash: '{mech.name}' has no {missing} actuator for {given}; set "
                f"{other} for its actuators (or use 'backlash')"
            )
        return play

    def directions(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        """Side of the last motion (+1 up, -1 down, 0 never moved) at each pose (N, A)."""
        seq = np.argsort(np.asarray(order), kind="stable")
        last = np.zeros(mech.n_actuators)
        previous = mech.home_qpos[mech.actuator_qpos].copy()
        out = np.zeros_like(commands, dtype=float)
        for i in seq:
            step = np.sign(commands[i] - previous)
            last = np.where(step != 0, step, last)
            out[i] = last
            previous = commands[i]
        return out

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        play = self.plays(mech)
        if not np.any(play):
            return commands
        side = self.directions(mech, commands, order)
        shift = 0.5 * play[None, :] * side
        return np.where(shift != 0.0, commands - shift, commands)
