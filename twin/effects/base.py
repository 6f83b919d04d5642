"""The common shape of actuator-side effects: commanded values in, true joint values out."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from twin.mechanism import Mechanism


class ActuatorEffect(Protocol):
    name: str

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        """True joint values (N, A) for commands (N, A) measured in sequence ``order`` (N,)."""
        ...


def apply_actuator_effects(
    mech: Mechanism,
    effects: Sequence[ActuatorEffect],
    commands: np.ndarray,
    order: np.ndarray | None = None,
) -> np.ndarray:
    """Apply the effects in turn; ``order`` defaults to the row order (measurement sequence)."""
    commands = np.atleast_2d(np.asarray(commands, dtype=float))
    order = np.arange(len(commands)) if order is None else np.asarray(order)
    out = commands
    for effect in effects:
        out = effect.apply(mech, out, order)
    return out
