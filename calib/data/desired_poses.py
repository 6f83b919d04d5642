"""Desired tool poses a user asks the machine to reach: a CSV in millimetres and degrees.

    pose_id,x_mm,y_mm,z_mm[,rx_deg,ry_deg,rz_deg]

One row per pose; ``pose_id`` is any unique label. The orientation is ``R = Rz(rz) Ry(ry)
Rx(rx)`` of the tool frame; a row that leaves the three orientation cells empty (or a file
without those columns) asks for a position only, and the tool keeps the nominal orientation
(that of the nominal model at its home configuration). Blank lines and lines starting with
``#`` are skipped. UTF-8 (a byte-order mark is accepted). A malformed file raises
:class:`DesiredPosesError` naming the file, line and column; nothing is guessed.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.exceptions import CalibError
from twin.formats.parameter_file import closest, read_utf8

POSITION = ("x_mm", "y_mm", "z_mm")
ORIENTATION = ("rx_deg", "ry_deg", "rz_deg")
COLUMNS = ("pose_id", *POSITION, *ORIENTATION)


class DesiredPosesError(CalibError):
    """A desired-pose file that cannot be read (the message names file, line and column)."""


@dataclass(frozen=True)
class DesiredPoses:
    """Poses as read, SI: positions (N, 3) in metres; orientations (N, 3) rpy in radians,
    NaN on the rows that ask for a position only."""

    path: Path
    pose_ids: tuple[str, ...]
    positions: np.ndarray
    rpy: np.ndarray

    @property
    def has_orientation(self) -> np.ndarray:
        return ~np.isnan(self.rpy[:, 0])

    def __len__(self) -> int:
        return len(self.pose_ids)


def _header(path: Path, line: int, cells: list[str]) -> dict[str, int]:
    columns: dict[str, int] = {}
    for k, cell in enumerate(cells):
        name = cell.strip()
        if name not in COLUMNS:
            raise DesiredPosesError(
                f"{path}, line {line}: unknown column '{name}'{closest(name, COLUMNS)}; the "
                f"columns are pose_id,x_mm,y_mm,z_mm and optionally rx_deg,ry_deg,rz_deg"
            )
        if name in columns:
            raise DesiredPosesError(f"{path}, line {line}: column '{name}' appears twice")
        columns[name] = k
    missing = [c for c in ("pose_id", *POSITION) if c not in columns]
    if missing:
        raise DesiredPosesError(f"{path}, line {line}: missing column(s) {missing}")
    some = [c for c in ORIENTATION if c in columns]
    if some and len(some) != 3:
        lack = [c for c in ORIENTATION if c not in columns]
        raise DesiredPosesError(
            f"{path}, line {line}: orientation columns {some} without {lack}: give all three "
            "or none"
        )
    return columns


def cell_number(
    path: Path, line: int, column: str, text: str, error: type[Exception] = ValueError
) -> float:
    """A CSV cell's finite number; ``error`` (the reader's own) names file, line and column."""
    try:
        value = float(text)
    except ValueError:
        raise error(f"{path}, line {line}, column '{column}': '{text}' is not a number") from None
    if not math.isfinite(value):
        raise error(f"{path}, line {line}, column '{column}': '{text}' is not a finite number")
    return value


def _number(path: Path, line: int, column: str, text: str) -> float:
    return cell_number(path, line, column, text, DesiredPosesError)


def read_desired_poses(path: str | os.PathLike[str]) -> DesiredPoses:
    """Read a desired-pose CSV (format in the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise DesiredPosesError(f"desired-pose file not found: {path}")
    try:
        text = read_utf8(path)
    except UnicodeError as exc:
        raise DesiredPosesError(f"{path}: {exc}") from None
    columns: dict[str, int] | None = None
    ids: list[str] = []
    positions: list[list[float]] = []
    rpy: list[list[float]] = []
    for line, raw in enumerate(text.splitlines(), start=1):
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        cells = [c.strip() for c in next(csv.reader([raw]))]
        if columns is None:
            columns = _header(path, line, cells)
            continue
        if len(cells) != len(columns):
            raise DesiredPosesError(
                f"{path}, line {line}: {len(cells)} cells for {len(columns)} columns"
            )
        pid = cells[columns["pose_id"]]
        if not pid:
            raise DesiredPosesError(f"{path}, line {line}, column 'pose_id': empty")
        if pid in ids:
            raise DesiredPosesError(f"{path}, line {line}: pose_id '{pid}' appears twice")
        ids.append(pid)
        positions.append([_number(path, line, c, cells[columns[c]]) * 1e-3 for c in POSITION])
        given = [c for c in ORIENTATION if c in columns and cells[columns[c]]]
        if given and len(given) != 3:
            lack = [c for c in ORIENTATION if c not in given]
            raise DesiredPosesError(
                f"{path}, line {line}: pose_id '{pid}' gives {given} but not {lack}: give all "
                "three, or none to keep the nominal orientation"
            )
        rpy.append(
            [math.radians(_number(path, line, c, cells[columns[c]])) for c in ORIENTATION]
            if given
            else [math.nan] * 3
        )
    if columns is None:
        raise DesiredPosesError(f"{path}: empty file (no header pose_id,x_mm,y_mm,z_mm)")
    if not ids:
        raise DesiredPosesError(f"{path}: no pose rows after the header")
    return DesiredPoses(path, tuple(ids), np.array(positions), np.array(rpy))
