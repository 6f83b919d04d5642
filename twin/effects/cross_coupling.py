"""Cross coupling: a joint deflects by an amount that depends on other joints' positions.

In a cable-driven or belt-driven arm the cables of the distal joints run through the
proximal ones: their tension and routing change with the configuration, and so does the
torque they put on the joints they pass (a WAM's cables; a SCARA's belt through its elbow).
Each actuator i is deflected by ``a_i sin(c_j) cos(c_k)`` with two other actuators j, k:
a smooth, configuration-dependent error that is neither a joint's own periodic error, a gain,
a play, nor a load under gravity. Default: amplitudes drawn within +-``magnitude_rad``
(0.05 deg), j and k drawn among the other actuators (seeded); ``terms`` gives them
explicitly as (i, j, k, a_i rad) per term.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twin.effects._checks import finite, seed
from twin.exceptions import ModelError
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class CrossCoupling:
    magnitude_rad: float = float(np.radians(0.05))
    terms: tuple[tuple[int, int, int, float], ...] = field(default=())
    seed: int = 0
    name: str = "cross_coupling"

    def __post_init__(self) -> None:
        finite(self.magnitude_rad, "magnitude_rad", min=0.0)
        seed(self.seed)
        for t in self.terms:
            if len(t) != 4 or not np.isfinite(t[3]):
                raise ValueError(f"a cross_coupling term is (i, j, k, amplitude rad), got {t}")

    def coupling(self, mech: Mechanism) -> tuple[tuple[int, int, int, float], ...]:
        """The terms (i, j, k, a_i) on this mechanism."""
        n = mech.n_actuators
        if any(mech.actuator_is_slide):
            raise ModelError("cross_coupling is of revolute joints (sines of their angles)")
        if self.terms:
            bad = [t for t in self.terms if not all(0 <= int(x) < n for x in t[:3])]
            if bad:
                raise ModelError(f"cross_coupling terms {bad} name no actuator of {n}")
            return self.terms
        if n < 3:
            raise ModelError("cross_coupling draws two other actuators per actuator: needs 3")
        rng = np.random.default_rng(self.seed)
        out = []
        for i in range(n):
            others = [a for a in range(n) if a != i]
            j, k = rng.choice(others, size=2, replace=False)
            out.append((i, int(j), int(k), float(rng.uniform(-1.0, 1.0) * self.magnitude_rad)))
        return tuple(out)

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        c = np.asarray(commands, dtype=float)
        out = c.copy()
        for i, j, k, a in self.coupling(mech):
            out[:, i] += a * np.sin(c[:, j]) * np.cos(c[:, k])
        return out
