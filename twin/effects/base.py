"""The common shapes of the twin's physical effects, and how a measurement applies them.

An effect is a frozen dataclass with a ``name`` and one or more of four hooks; the measurement
(:func:`twin.measurement.measure`) calls each hook an effect has, in this order:

1. ``apply(mech, commands, order) -> joints`` (:class:`ActuatorEffect`): commanded actuator
   values (N, A) in, the joint values the machine really takes out (backlash, lead error,
   gain, compliance, the travel of a warm screw). ``order`` (N,) is the measurement sequence.
2. ``model_at(mech, k) -> Mechanism`` (:class:`GeometryEffect`): the machine's geometry at the
   k-th pose in measurement order (thermal growth of links, base and platform); it returns
   ``mech`` itself when nothing changes, so a zero magnitude leaves the truth untouched.
3. ``target_offsets(mech) -> (T, 3)`` (:class:`TargetEffect`): where each reflector really
   sits relative to its nominal site, in the tool frame (SMR centring and nest tolerance).
4. ``on_tracker(tracker) -> Tracker`` (:class:`ReadingEffect`): the instrument as it really
   measures (a distance scale from a wrong air temperature).

Every effect is deterministic given its parameters; random draws come only from its ``seed``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from twin.mechanism import Mechanism

if TYPE_CHECKING:
    from twin.tracker import Tracker


@runtime_checkable
class Effect(Protocol):
    name: str


@runtime_checkable
class ActuatorEffect(Protocol):
    name: str

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        """True joint values (N, A) for commands (N, A) measured in sequence ``order`` (N,)."""
        ...


@runtime_checkable
class GeometryEffect(Protocol):
    name: str

    def model_at(self, mech: Mechanism, k: int) -> Mechanism:
        """The machine at the k-th pose of the measurement sequence (``mech`` if unchanged)."""
        ...


@runtime_checkable
class TargetEffect(Protocol):
    name: str

    def target_offsets(self, mech: Mechanism) -> np.ndarray:
        """True minus nominal position of each target (T, 3), metres, in the tool frame."""
        ...


@runtime_checkable
class ReadingEffect(Protocol):
    name: str

    def on_tracker(self, tracker: Tracker) -> Tracker:
        """The tracker as it really measures with this effect."""
        ...


def apply_actuator_effects(
    mech: Mechanism,
    effects: Sequence[Effect],
    commands: np.ndarray,
    order: np.ndarray | None = None,
) -> np.ndarray:
    """Apply the actuator-side effects in turn (others are skipped); ``order`` defaults to the
    row order (measurement sequence)."""
    commands = np.atleast_2d(np.asarray(commands, dtype=float))
    order = np.arange(len(commands)) if order is None else np.asarray(order)
    out = commands
    for effect in effects:
        if isinstance(effect, ActuatorEffect):
            out = effect.apply(mech, out, order)
    return out


def model_at(mech: Mechanism, effects: Sequence[Effect], k: int) -> Mechanism:
    """The machine at the k-th pose in measurement order after every geometry effect."""
    out = mech
    for effect in effects:
        if isinstance(effect, GeometryEffect):
            out = effect.model_at(out, int(k))
    return out


def target_offsets(mech: Mechanism, effects: Sequence[Effect]) -> np.ndarray:
    """Sum of the target offsets (T, 3) in the tool frame of every target effect."""
    out = np.zeros((mech.n_targets, 3))
    for effect in effects:
        if isinstance(effect, TargetEffect):
            out = out + np.asarray(effect.target_offsets(mech), dtype=float)
    return out


def tracker_with(tracker: Tracker, effects: Sequence[Effect]) -> Tracker:
    """The tracker after every reading effect."""
    for effect in effects:
        if isinstance(effect, ReadingEffect):
            tracker = effect.on_tracker(tracker)
    return tracker


def check_effects(effects: Sequence[object]) -> None:
    """Every effect has a name and at least one hook; a clear error otherwise."""
    hooks = (ActuatorEffect, GeometryEffect, TargetEffect, ReadingEffect)
    for e in effects:
        if not isinstance(e, Effect) or not any(isinstance(e, h) for h in hooks):
            raise TypeError(
                f"{e!r} is not an effect: it needs a 'name' and one of apply(), model_at(), "
                "target_offsets(), on_tracker()"
            )
