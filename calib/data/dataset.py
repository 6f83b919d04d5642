"""Measured datasets: the contract between a measuring machine and the calibration.

On disk a dataset is a CSV file with one row per (pose, target, repeat) plus a JSON
sidecar at ``<csv path>.json``; lengths are millimetres and angles degrees (format
details and parsing in :mod:`calib.data.dataset_io`). In memory (:class:`Dataset`)
everything is SI: metres and radians. Commanded tool poses use
``R = Rz(rz) @ Ry(ry) @ Rx(rx)`` (see :func:`twin.rotations.matrix_from_rpy`).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FORMAT = "pkm-calib-dataset"
VERSION = 1
ACTUATOR_UNITS = ("mm", "deg")


class DatasetError(ValueError):
    """An invalid dataset file or inconsistent dataset contents."""


def sidecar_path(csv_path: str | os.PathLike[str]) -> Path:
    """Path of the JSON sidecar belonging to ``csv_path`` (``<csv path>.json``)."""
    return Path(f"{os.fspath(csv_path)}.json")


def check_names(values: Sequence[str], what: str) -> tuple[str, ...]:
    """Names as a tuple; raises DatasetError unless non-empty, unique and unpadded."""
    names = tuple(values)
    bad = [n for n in names if not isinstance(n, str) or not n or n != n.strip()]
    if bad:
        raise DatasetError(f"{what} names must be non-empty strings without padding: {bad}")
    if not names or len(set(names)) != len(names):
        raise DatasetError(f"{what} names must be non-empty and unique: {list(names)}")
    return names


QUAT_UNIT_TOLERANCE = 1e-6  # |q| - 1 beyond this is no unit quaternion


def checked_orientations(value: object, shape: tuple[int, int, int]) -> np.ndarray:
    """Orientations (P, T, R, 4), NaN for targets without one: each target has them at every
    pose and repeat or at none, each a unit quaternion."""
    arr = np.array(value, dtype=float)
    if arr.shape != (*shape, 4):
        raise DatasetError(f"orientations has shape {arr.shape}, expected {(*shape, 4)}")
    finite = np.isfinite(arr).all(axis=-1)
    per_target = finite.transpose(1, 0, 2).reshape(shape[1], -1)
    mixed = np.flatnonzero(per_target.any(axis=1) & ~per_target.all(axis=1))
    if mixed.size:
        raise DatasetError(
            f"target index {int(mixed[0])} has an orientation at some rows and not at others"
        )
    if np.any(np.isfinite(arr).any(axis=-1) & ~finite):
        raise DatasetError("a quaternion is partly given (all four values or none)")
    norms = np.linalg.norm(np.where(finite[..., None], arr, 0.0), axis=-1)
    if np.any(finite & (np.abs(norms - 1.0) > QUAT_UNIT_TOLERANCE)):
        raise DatasetError("orientations must be unit quaternions (w, x, y, z)")
    arr.setflags(write=False)
    return arr


def oriented_targets(orientations: np.ndarray | None, n_targets: int) -> np.ndarray:
    """(T,) bool: which targets carry an orientation."""
    if orientations is None:
        return np.zeros(n_targets, dtype=bool)
    return np.isfinite(orientations).all(axis=-1).all(axis=(0, 2))


def _array(value: Any, name: str, shape: tuple[int, ...], integer: bool = False) -> np.ndarray:
    """Read-only copy of ``value`` checked against ``shape`` (-1 = any size >= 1)."""
    arr = np.array(value)
    kinds = "iu" if integer else "iuf"
    if arr.dtype.kind not in kinds:
        raise DatasetError(f"{name} must be {'integer' if integer else 'real'}, got {arr.dtype}")
    arr = arr.astype(np.int64 if integer else np.float64)
    ok = arr.ndim == len(shape) and all(
        n == s or (s == -1 and n >= 1) for n, s in zip(arr.shape, shape, strict=False)
    )
    if not ok:
        raise DatasetError(f"{name} has shape {arr.shape}, expected {shape} (-1: any size >= 1)")
    if not np.all(np.isfinite(arr)):
        raise DatasetError(f"{name} contains NaN or inf values")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Dataset:
    """Target positions measured at commanded poses; SI units (metres, radians).

    ``readings[p, t, r]`` is target ``t`` at pose ``p``, repeat ``r``, in ``frame``;
    ``commands[p, a]`` is the command of actuator ``a`` (metres for "mm" actuators,
    radians for "deg" ones). ``commanded_poses`` rows are ``[x, y, z, rx, ry, rz]``.
    """

    model: str
    frame: str
    actuator_names: tuple[str, ...]
    actuator_units: tuple[str, ...]
    target_names: tuple[str, ...]
    pose_ids: NDArray[np.int64]
    sets: NDArray[np.str_]
    commands: NDArray[np.float64]
    readings: NDArray[np.float64]
    order: NDArray[np.int64] | None = None
    time_s: NDArray[np.float64] | None = None
    # the temperature at each reading (deg C), and each actuator's approach direction (+1/-1,
    # 0: it did not move), for the error model's thermal and backlash kinds
    temperature_c: NDArray[np.float64] | None = None
    direction: NDArray[np.float64] | None = None
    commanded_poses: NDArray[np.float64] | None = None
    # (P, T, R, 4) unit quaternions (w, x, y, z) of the targets' frames, NaN for targets
    # without one (calib.data.orientation_columns)
    orientations: NDArray[np.float64] | None = None
    tracker: dict[str, Any] | None = None
    meta: dict[str, Any] | None = None
    notes: str = ""

    def __post_init__(self) -> None:
        def put(key: str, value: Any) -> None:
            object.__setattr__(self, key, value)

        for key in ("model", "frame"):
            if not isinstance(getattr(self, key), str) or not getattr(self, key):
                raise DatasetError(f"{key} must be a non-empty string")
        acts = check_names(self.actuator_names, "actuator")
        units = tuple(self.actuator_units)
        if len(units) != len(acts) or any(u not in ACTUATOR_UNITS for u in units):
            raise DatasetError(
                f"actuator_units {list(units)} must give one of {ACTUATOR_UNITS} per actuator"
            )
        targets = check_names(self.target_names, "target")
        put("actuator_names", acts)
        put("actuator_units", units)
        put("target_names", targets)
        pose_ids = _array(self.pose_ids, "pose_ids", (-1,), integer=True)
        n = len(pose_ids)
        if len(np.unique(pose_ids)) != n:
            raise DatasetError(f"pose_ids must be unique: {pose_ids.tolist()}")
        put("pose_ids", pose_ids)
        sets = np.array([str(s) for s in np.asarray(self.sets).reshape(-1)])
        if sets.shape != (n,) or any(not s or s != s.strip() for s in sets):
            raise DatasetError(f"sets must be {n} non-empty unpadded strings")
        sets.setflags(write=False)
        put("sets", sets)
        put("commands", _array(self.commands, "commands", (n, len(acts))))
        put("readings", _array(self.readings, "readings", (n, len(targets), -1, 3)))
        if self.order is not None:
            put("order", _array(self.order, "order", (n,), integer=True))
        if self.time_s is not None:
            put("time_s", _array(self.time_s, "time_s", (n,)))
        if self.temperature_c is not None:
            put("temperature_c", _array(self.temperature_c, "temperature_c", (n,)))
        if self.direction is not None:
            d = _array(self.direction, "direction", (n, len(acts)))
            if not np.all(np.isin(d, (-1.0, 0.0, 1.0))):
                raise DatasetError(
                    "direction (the dir:<actuator> columns) must be +1 or -1 (0: the actuator "
                    f"did not move), got {sorted(set(d[~np.isin(d, (-1.0, 0.0, 1.0))]))[:3]}"
                )
            put("direction", d)
        if self.commanded_poses is not None:
            put("commanded_poses", _array(self.commanded_poses, "commanded_poses", (n, 6)))
        if self.orientations is not None:
            put("orientations", checked_orientations(self.orientations, self.readings.shape[:3]))
        for key in ("tracker", "meta"):
            if getattr(self, key) is not None and not isinstance(getattr(self, key), dict):
                raise DatasetError(f"{key} must be a dict or None")
        if not isinstance(self.notes, str):
            raise DatasetError("notes must be a string")

    @property
    def oriented(self) -> NDArray[np.bool_]:
        """(T,) which targets carry an orientation (a 6-DoF probe)."""
        return oriented_targets(self.orientations, self.n_targets)

    @property
    def n_poses(self) -> int:
        return int(self.readings.shape[0])

    @property
    def n_targets(self) -> int:
        return int(self.readings.shape[1])

    @property
    def n_repeats(self) -> int:
        return int(self.readings.shape[2])

    @property
    def pose_labels(self) -> tuple[str, ...]:
        """The pose ids as strings, to name poses in errors (e.g. the ``labels`` of
        :func:`twin.workspace.check_command_strokes`), never their row index."""
        return tuple(str(int(i)) for i in self.pose_ids)

    @property
    def measured(self) -> NDArray[np.float64]:
        """Mean over repeats, (P, T, 3) metres."""
        return self.readings.mean(axis=2)

    @property
    def repeat_std(self) -> NDArray[np.float64]:
        """Sample standard deviation over repeats (ddof=1), (P, T, 3); zeros if R == 1."""
        if self.n_repeats == 1:
            return np.zeros_like(self.measured)
        return self.readings.std(axis=2, ddof=1)

    def subset(self, selection: ArrayLike) -> Dataset:
        """Poses chosen by a boolean mask of length P or by integer indices."""
        sel = np.asarray(selection)
        if sel.dtype == bool:
            if sel.shape != (self.n_poses,):
                raise DatasetError(f"mask has shape {sel.shape}, expected ({self.n_poses},)")
            idx = np.flatnonzero(sel)
        elif sel.dtype.kind in "iu" or sel.size == 0:
            idx = sel.astype(np.int64).reshape(-1)
        else:
            raise DatasetError(f"selection must be a boolean mask or integers, got {sel.dtype}")
        if idx.size == 0:
            raise DatasetError("selection contains no poses")
        if np.any((idx < -self.n_poses) | (idx >= self.n_poses)):
            raise DatasetError(f"pose index out of range for {self.n_poses} poses: {idx.tolist()}")

        def take(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[idx]

        return dataclasses.replace(
            self,
            pose_ids=self.pose_ids[idx],
            sets=self.sets[idx],
            commands=self.commands[idx],
            readings=self.readings[idx],
            order=take(self.order),
            time_s=take(self.time_s),
            temperature_c=take(self.temperature_c),
            direction=take(self.direction),
            commanded_poses=take(self.commanded_poses),
            orientations=take(self.orientations),
        )

    def select_set(self, name: str) -> Dataset:
        """Poses whose ``set`` equals ``name``."""
        mask = self.sets == name
        if not mask.any():
            raise DatasetError(f"no poses in set {name!r}; sets present: {sorted(set(self.sets))}")
        return self.subset(mask)

    def check_against(self, actuator_names: Sequence[str], target_names: Sequence[str]) -> None:
        """Raise DatasetError unless the names match a model's (order may differ)."""
        problems = []
        for kind, have, want in (
            ("actuator", self.actuator_names, actuator_names),
            ("target", self.target_names, target_names),
        ):
            missing = [n for n in want if n not in have]
            unknown = [n for n in have if n not in want]
            if missing:
                problems.append(f"missing {kind}s {missing}")
            if unknown:
                problems.append(f"unknown {kind}s {unknown}")
        if problems:
            raise DatasetError(f"dataset for model {self.model!r}: " + "; ".join(problems))

    def reordered(self, actuator_names: Sequence[str], target_names: Sequence[str]) -> Dataset:
        """The same data with actuators and targets in the given order."""
        self.check_against(actuator_names, target_names)
        a = [self.actuator_names.index(n) for n in actuator_names]
        t = [self.target_names.index(n) for n in target_names]
        return dataclasses.replace(
            self,
            actuator_names=tuple(actuator_names),
            actuator_units=tuple(self.actuator_units[i] for i in a),
            target_names=tuple(target_names),
            commands=self.commands[:, a],
            readings=self.readings[:, t],
            direction=None if self.direction is None else self.direction[:, a],
            orientations=None if self.orientations is None else self.orientations[:, t],
        )
