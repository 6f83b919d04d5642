"""Where the planned poses come from: random reachable poses of the workspace, or a user's own
pool of poses known to be safe (a Dataset or a program CSV).

A candidate is a row of actuator commands (SI: m, rad, the model's actuator order) with a
label: its ``pose_id`` in the file it came from, or its draw number."""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.data.dataset import sidecar_path
from calib.data.dataset_io import read_dataset
from calib.exceptions import CalibError
from twin.mechanism import Mechanism
from twin.workspace import random_poses

CMD = "cmd:"


@dataclass(frozen=True)
class Candidates:
    commands: np.ndarray  # (C, A) SI
    labels: tuple[str, ...]  # pose_id in the source, or the draw number
    source: str  # in words, for the printout

    def __len__(self) -> int:
        return len(self.labels)


def workspace_candidates(mech: Mechanism, n: int, rng: np.random.Generator) -> Candidates:
    """``n`` random reachable poses: uniform in the workspace box the model declares
    (twin.workspace.random_poses: nominal inverse kinematics inside the strokes), else,
    for a model without one (a serial arm generated from a table), uniform commands within
    the actuators' ranges."""
    if mech.workspace_min is not None and mech.workspace_max is not None:
        _, commands = random_poses(mech, n, rng)
        what = "random reachable poses of the workspace box"
    else:
        lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
        commands = rng.uniform(lo, hi, size=(n, mech.n_actuators))
        what = "random commands within the actuators' ranges"
    return Candidates(commands, tuple(str(k) for k in range(n)), f"{n} {what}")


def file_candidates(
    path: str | os.PathLike[str], mech: Mechanism, set_name: str | None
) -> Candidates:
    """The poses of a Dataset (CSV with its sidecar) or of a program CSV (``pose_id``,
    ``cmd:<actuator>`` in mm or deg, optional ``set``), the rows of ``set_name`` if given."""
    path = Path(path)
    if not path.is_file():
        raise CalibError(f"--candidates: file not found: {path}")
    if sidecar_path(path).is_file():
        ds = read_dataset(path, expected_model=mech.name)
        ds.check_against(mech.actuator_names, mech.target_names)
        ds = ds.reordered(mech.actuator_names, mech.target_names)
        keep = np.ones(ds.n_poses, bool) if set_name is None else ds.sets == set_name
        if not np.any(keep):
            raise CalibError(
                f"--candidates {path}: no pose in set '{set_name}'; its sets are "
                f"{sorted(set(ds.sets.tolist()))}"
            )
        labels = tuple(str(p) for p in ds.pose_ids[keep].tolist())
        what = f"{int(keep.sum())} poses of the dataset {path}"
        return Candidates(np.array(ds.commands)[keep], labels, what + _in_set(set_name))
    return _program_candidates(path, mech, set_name)


def _in_set(set_name: str | None) -> str:
    return "" if set_name is None else f" (set '{set_name}')"


def _program_candidates(path: Path, mech: Mechanism, set_name: str | None) -> Candidates:
    """A program CSV: one row per pose, mm for prismatic and deg for revolute actuators."""
    with open(path, newline="", encoding="utf-8-sig") as f:
        rows = [r for r in csv.reader(f) if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise CalibError(f"--candidates {path}: empty file")
    head = [c.strip() for c in rows[0]]
    wanted = [CMD + a for a in mech.actuator_names]
    missing = [w for w in ["pose_id", *wanted] if w not in head]
    if missing:
        raise CalibError(
            f"--candidates {path}: no column(s) {missing}: a program CSV has pose_id and "
            f"cmd:<actuator> (mm or deg) for {list(mech.actuator_names)}; a Dataset needs its "
            f"sidecar {sidecar_path(path).name}"
        )
    if set_name is not None and "set" not in head:
        raise CalibError(
            f"--candidates {path}: --set {set_name} given but the file has no set column"
        )
    scale = np.where(mech.actuator_is_slide, 1e-3, math.pi / 180.0)
    cols = [head.index(w) for w in wanted]
    seen: dict[str, np.ndarray] = {}
    for line, cells in enumerate(rows[1:], start=2):
        if len(cells) != len(head):
            raise CalibError(
                f"--candidates {path}, line {line}: {len(cells)} cells for {len(head)} columns"
            )
        if set_name is not None and cells[head.index("set")].strip() != set_name:
            continue
        pid = cells[head.index("pose_id")].strip()
        try:
            values = np.array([float(cells[c]) for c in cols])
        except ValueError:
            raise CalibError(
                f"--candidates {path}, line {line}: a command is not a number"
            ) from None
        if not np.all(np.isfinite(values)):
            raise CalibError(f"--candidates {path}, line {line}: a command is not finite")
        if pid in seen and not np.array_equal(seen[pid], values):
            raise CalibError(
                f"--candidates {path}, line {line}: pose_id {pid} given twice with other commands"
            )
        seen.setdefault(pid, values)
    if not seen:
        raise CalibError(f"--candidates {path}: no pose{_in_set(set_name)}")
    commands = np.array(list(seen.values())) * scale
    return Candidates(
        commands, tuple(seen), f"{len(seen)} poses of the program {path}{_in_set(set_name)}"
    )
