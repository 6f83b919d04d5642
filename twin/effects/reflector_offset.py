"""Reflector offsets: each SMR's centre sits a little off its nominal site on the tool.

A spherically mounted retroreflector rests in a kinematic nest; its optical centre misses the
nest's nominal point by the ball's centring error (grade-dependent, 2.5-13 um for 1.5" SMRs)
plus the nest's position and seat tolerance on the tool (tens of micrometres for a drilled
and reamed seat, a glued magnet nest or an adaptor). The effect shifts every target by a
constant offset in the tool frame, so the reading moves by R_tool @ offset.

Default: 30 um per target (10-100 um is the range of nests on machine tools and robots), in
a direction drawn uniformly on the sphere (seeded), or ``offsets_m`` explicitly (T x 3
values, target-major, tool frame).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twin.effects._checks import finite, floats, seed
from twin.exceptions import ModelError
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class ReflectorOffset:
    magnitude_m: float = 30e-6  # |offset| of each target when drawn
    offsets_m: tuple[float, ...] = field(default=())  # T x 3, tool frame; () draws them
    seed: int = 0
    name: str = "reflector_offset"

    def __post_init__(self) -> None:
        finite(self.magnitude_m, "magnitude_m", min=0.0)
        object.__setattr__(self, "offsets_m", floats(self.offsets_m, "offsets_m"))
        if len(self.offsets_m) % 3:
            raise ValueError(f"offsets_m holds x, y, z per target, got {len(self.offsets_m)}")
        seed(self.seed)

    def target_offsets(self, mech: Mechanism) -> np.ndarray:
        n = mech.n_targets
        if self.offsets_m:
            if len(self.offsets_m) != 3 * n:
                raise ModelError(
                    f"reflector_offset needs 3 x {n} offsets for {mech.target_names}, "
                    f"got {len(self.offsets_m)}"
                )
            return np.reshape(self.offsets_m, (n, 3))
        if self.magnitude_m == 0.0:
            return np.zeros((n, 3))
        rng = np.random.default_rng(self.seed)
        u = rng.standard_normal((n, 3))
        return self.magnitude_m * u / np.linalg.norm(u, axis=1, keepdims=True)
