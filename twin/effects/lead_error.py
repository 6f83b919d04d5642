"""Periodic lead error of the ball screws: a function of the actuator position.

A prismatic actuator commanded to q travels q + A sin(2 pi q / pitch + phase_i): the screw's
periodic error with amplitude A (a few micrometres) and one period per lead ``pitch``; each
actuator has its own phase (its screw is mounted at its own angle).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twin.mechanism import Mechanism


@dataclass(frozen=True)
class LeadError:
    amplitude_m: float = 5e-6
    pitch_m: float = 5e-3
    phases_rad: tuple[float, ...] = field(default=())
    name: str = "lead_error"

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        n = commands.shape[1]
        phase = np.asarray(self.phases_rad or np.linspace(0, 2 * np.pi, n, endpoint=False))
        if phase.shape != (n,):
            raise ValueError(f"lead error needs {n} phases, got {phase.shape}")
        wave = self.amplitude_m * np.sin(2 * np.pi * commands / self.pitch_m + phase)
        return np.where(mech.actuator_is_slide[None, :], commands + wave, commands)
