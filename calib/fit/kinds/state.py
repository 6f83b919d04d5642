"""The state of the machine at each reading that the offset kinds read beside the commands.

* ``direction`` (P, A): the sign (+1 / -1) of each actuator's last motion before the reading,
  from the dataset's ``dir:<actuator>`` columns when it has them, else derived from the
  commands' sequence in ``order`` (:func:`with_directions`): the previous pose in order,
  whatever its set, the first pose approached from the model's home configuration; 0 for an
  actuator that did not move (no direction: no offset);
* ``time_s`` and ``order`` (P,): when each pose was measured (the clocks of the time kinds);
* ``temperature_c`` (P,): the temperature at the reading (thermal expansion).

``source`` says where the directions came from, for the printouts.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from calib.data.dataset import Dataset, DatasetError

COLUMN = "the dataset's dir:<actuator> columns"
HOME = "the model's home configuration"


@dataclass(frozen=True)
class PoseState:
    """What the offset kinds read at each of P readings (None: the dataset lacks it)."""

    n: int
    direction: np.ndarray | None = None  # (P, A)
    time_s: np.ndarray | None = None  # (P,)
    order: np.ndarray | None = None  # (P,)
    temperature_c: np.ndarray | None = None  # (P,)
    source: str = ""  # where the directions came from

    @classmethod
    def of(cls, dataset: Dataset) -> PoseState:
        """The state of a dataset's poses, in its row order."""
        meta = dataset.meta or {}
        return cls(
            dataset.n_poses,
            None if dataset.direction is None else np.asarray(dataset.direction, dtype=float),
            None if dataset.time_s is None else np.asarray(dataset.time_s, dtype=float),
            None if dataset.order is None else np.asarray(dataset.order, dtype=float),
            None if dataset.temperature_c is None else np.asarray(dataset.temperature_c, float),
            str(meta.get("direction_source", COLUMN if dataset.direction is not None else "")),
        )

    def column(self, name: str, who: str) -> np.ndarray:
        """The state ``name`` ("direction", "time_s", "order", "temperature_c"); a clear
        error naming ``who`` needs it when the dataset lacks it."""
        value = getattr(self, name)
        if value is not None:
            return value
        if name == "direction":
            raise DatasetError(
                f"{who} needs each actuator's approach direction: the dataset has neither "
                "dir:<actuator> columns (+1/-1) nor an order column to derive it from"
            )
        raise DatasetError(f"{who} needs the dataset's '{name}' column, which it lacks")


def approach_directions(commands: np.ndarray, order: np.ndarray, home: np.ndarray) -> np.ndarray:
    """(P, A): the sign of each actuator's last motion before each pose, the poses measured in
    ``order`` from ``home`` (A,); 0 where an actuator did not move (the diagnosis's
    convention: calib.diagnosis.context.approach_direction)."""
    commands = np.asarray(commands, dtype=float)
    seq = np.argsort(np.asarray(order), kind="stable")
    prev = np.vstack([np.asarray(home, dtype=float), commands[seq][:-1]])
    step = np.sign(commands[seq] - prev)
    out = np.zeros_like(commands)
    out[seq] = step
    return out


def state_for(model: Any, dataset: Dataset) -> Dataset:
    """``dataset`` ready for ``model`` (a CalibrationModel): with the approach directions
    derived over all its poses when an offset kind needs them and it has no dir: columns."""
    offsets = getattr(model, "offsets", None)
    if offsets is None or "direction" not in offsets.needs:
        return dataset
    mech = model.nominal
    return with_directions(dataset, mech.home_qpos[mech.actuator_qpos])


def with_directions(dataset: Dataset, home: np.ndarray) -> Dataset:
    """``dataset`` with the approach directions: its own ``dir:`` columns, else derived over
    all its poses (every set) from ``order`` (none without an order: left to the kinds that
    need it to refuse)."""
    if dataset.direction is not None or dataset.order is None:
        return dataset
    derived = approach_directions(dataset.commands, dataset.order, home)
    source = (
        "derived from the order column (each pose approached from the previous one in order, "
        f"the first from {HOME})"
    )
    meta = {**(dataset.meta or {}), "direction_source": source}
    return dataclasses.replace(dataset, direction=derived, meta=meta)
