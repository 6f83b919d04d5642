"""Ball-screw lead error: a cumulative lead deviation plus harmonics of the screw revolution.

A prismatic actuator driven by a screw of lead ``pitch_m`` (metres per revolution) and
commanded to travel s = q - q0 from its joint zero q0 really travels

    s + c_i s / 0.3 m + sum_h A_h sin(2 pi h s / pitch + phi_ih)

* c_i: the screw's mean travel deviation per 300 mm. ISO 3408-3 (JIS B 1192) bounds it by the
  accuracy class, e.g. +-12 um (C3) and +-23 um (C5) over a 315-400 mm thread, +-52 um/300 mm
  for C7; each screw's c_i is drawn uniformly within +-``cumulative_m_per_300mm`` (seeded);
* A_h, phi_ih: the periodic ("wobble") error of each revolution, h = 1, 2, ... times per
  revolution (run-out and thread form: 1x, ball recirculation and nut tilt: 2x). ISO 3408-3
  bounds its peak-to-peak by v_2pi = 6 um (C3), 8 um (C5); defaults 2.5 um at 1x and 1 um at
  2x (a C5 screw). The phases differ between screws (each mounted at its own angle): drawn
  uniformly (seeded) unless ``phases_rad`` gives them, actuator-major (A x H values).

Typical leads 4, 5, 10 mm. Only prismatic actuators have screws; revolute ones are untouched.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twin.effects._checks import finite, floats, seed
from twin.exceptions import ModelError
from twin.mechanism import Mechanism

PER_300MM = 0.3  # m, the reference length of ISO 3408-3 travel deviations


@dataclass(frozen=True)
class LeadErrorHarmonic:
    pitch_m: float = 5e-3
    amplitudes_m: tuple[float, ...] = (2.5e-6, 1.0e-6)  # at 1x, 2x, ... per revolution
    phases_rad: tuple[float, ...] = field(default=())  # A x H, actuator-major; () draws them
    cumulative_m_per_300mm: float = 23e-6  # bound of each screw's mean deviation (C5)
    seed: int = 0
    name: str = "lead_error_harmonic"

    def __post_init__(self) -> None:
        finite(self.pitch_m, "pitch_m", above=0.0)
        object.__setattr__(self, "amplitudes_m", floats(self.amplitudes_m, "amplitudes_m"))
        object.__setattr__(self, "phases_rad", floats(self.phases_rad, "phases_rad"))
        finite(self.cumulative_m_per_300mm, "cumulative_m_per_300mm", min=0.0)
        seed(self.seed)

    def screws(self, mech: Mechanism) -> np.ndarray:
        slide = mech.actuator_is_slide
        if not np.any(slide):
            raise ModelError(
                f"lead_error_harmonic: '{mech.name}' has no prismatic actuator, so no ball "
                "screw for a lead error to act on"
            )
        return slide

    def draws(self, mech: Mechanism) -> tuple[np.ndarray, np.ndarray]:
        """Per actuator: mean deviation per 300 mm (A,) and phases (A, H)."""
        n, h = mech.n_actuators, len(self.amplitudes_m)
        rng = np.random.default_rng(self.seed)
        c = self.cumulative_m_per_300mm * rng.uniform(-1.0, 1.0, n)
        drawn = rng.uniform(0.0, 2 * np.pi, (n, h))
        if not self.phases_rad:
            return c, drawn
        if len(self.phases_rad) != n * h:
            raise ModelError(
                f"lead_error_harmonic needs {n} x {len(self.amplitudes_m)} = {n * h} phases "
                f"for '{mech.name}', got {len(self.phases_rad)}"
            )
        return c, np.reshape(self.phases_rad, (n, h))

    def deviation(self, mech: Mechanism, commands: np.ndarray) -> np.ndarray:
        """Travel error (N, A) in metres at the commands (N, A); zero on revolute actuators."""
        slide = self.screws(mech)
        c, phase = self.draws(mech)
        s = np.asarray(commands, dtype=float) - mech.model.qpos0[mech.actuator_qpos][None, :]
        dev = c[None, :] * s / PER_300MM
        for j, a in enumerate(self.amplitudes_m):
            dev = dev + a * np.sin(2 * np.pi * (j + 1) * s / self.pitch_m + phase[None, :, j])
        return np.where(slide[None, :], dev, 0.0)

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        dev = self.deviation(mech, commands)
        return np.where(dev != 0.0, commands + dev, commands)
