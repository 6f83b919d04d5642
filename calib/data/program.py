"""A robot's program: the joint targets its controller runs, as a CSV in millimetres and degrees.

    pose_id,cmd:<actuator 1>,...,cmd:<actuator A>[,order][,time_s][,temperature_c]
        [,dir:<actuator 1>,...,dir:<actuator A>][,any other column]

One ``cmd:<actuator>`` column per actuator of the model (mm for a prismatic actuator, deg for
a revolute one: the units of datasets); ``pose_id`` is any label. Other columns are ignored,
so that a Dataset CSV (several rows per pose: targets, repeats) or a corrected commands file
is a program too: the rows of one ``pose_id`` must then give the same commands, and the
program holds one target per ``pose_id`` in the order of first appearance. Blank lines and
lines starting with ``#`` are skipped; ``order``, ``time_s``, ``temperature_c`` and the
``dir:<actuator>`` approach directions (+1/-1, every actuator or none) are the state at which
each target will run, for the error model's kinds that read it (calib.fit.kinds);
UTF-8 (a byte-order mark is accepted). A malformed
file raises :class:`ProgramError` naming the file, line and column; nothing is guessed.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.data.desired_poses import cell_number
from calib.exceptions import CalibError
from twin.formats.parameter_file import closest, read_utf8

CMD_PREFIX = "cmd:"
DIR_PREFIX = "dir:"
STATE_COLUMNS = ("order", "time_s", "temperature_c")


class ProgramError(CalibError):
    """A program file that cannot be read (the message names file, line and column)."""


@dataclass(frozen=True)
class Program:
    """Joint targets as read: one row of commands (SI: m, rad) per pose_id."""

    path: Path
    pose_ids: tuple[str, ...]
    commands: np.ndarray  # (N, A), the order of the model's actuators
    # the state columns given (order, time_s, temperature_c: (N,); direction: (N, A))
    state: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.pose_ids)


def _columns(path: Path, line: int, cells: list[str], actuators: Sequence[str]) -> dict[str, int]:
    names = [c.strip() for c in cells]
    if "pose_id" not in names:
        raise ProgramError(f"{path}, line {line}: no 'pose_id' column")
    wanted = [CMD_PREFIX + a for a in actuators]
    for name in names:
        if name.startswith(CMD_PREFIX) and name not in wanted:
            raise ProgramError(
                f"{path}, line {line}: column '{name}' names no actuator of the model"
                f"{closest(name, wanted)}; its actuators are {list(actuators)}"
            )
    for name in ["pose_id", *wanted]:
        if names.count(name) > 1:
            raise ProgramError(f"{path}, line {line}: column '{name}' appears twice")
    missing = [w for w in wanted if w not in names]
    if missing:
        raise ProgramError(
            f"{path}, line {line}: missing column(s) {missing}: a program gives every "
            "actuator's command (mm or deg)"
        )
    dirs = [DIR_PREFIX + a for a in actuators]
    given = [d for d in dirs if d in names]
    if given and len(given) != len(dirs):
        raise ProgramError(
            f"{path}, line {line}: missing approach-direction column(s) "
            f"{[d for d in dirs if d not in names]} (dir:<actuator> for every actuator or none)"
        )
    state = [c for c in STATE_COLUMNS if c in names] + given
    return {name: names.index(name) for name in ["pose_id", *wanted, *state]}


def _number(path: Path, line: int, column: str, text: str) -> float:
    return cell_number(path, line, column, text, ProgramError)


def read_program(
    path: str | os.PathLike[str], actuators: Sequence[str], is_slide: Sequence[bool]
) -> Program:
    """Read a program CSV (format in the module docstring) for a model whose actuators are
    ``actuators`` (prismatic where ``is_slide``)."""
    path = Path(path)
    if not path.is_file():
        raise ProgramError(f"program file not found: {path}")
    try:
        text = read_utf8(path)
    except UnicodeError as exc:
        raise ProgramError(f"{path}: {exc}") from None
    scale = np.where(np.asarray(is_slide, dtype=bool), 1e-3, math.pi / 180.0)
    columns: dict[str, int] | None = None
    width = 0
    rows: dict[str, tuple[int, np.ndarray]] = {}
    for line, raw in enumerate(text.splitlines(), start=1):
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        cells = [c.strip() for c in next(csv.reader([raw]))]
        if columns is None:
            columns, width = _columns(path, line, cells, actuators), len(cells)
            continue
        if len(cells) != width:
            raise ProgramError(f"{path}, line {line}: {len(cells)} cells for {width} columns")
        pid = cells[columns["pose_id"]]
        if not pid:
            raise ProgramError(f"{path}, line {line}, column 'pose_id': empty")
        values = np.array([_number(path, line, c, cells[columns[c]]) for c in list(columns)[1:]])
        if pid in rows and not np.array_equal(rows[pid][1], values):
            raise ProgramError(
                f"{path}, line {line}: pose_id '{pid}' has other commands than on line "
                f"{rows[pid][0]}: one pose_id is one joint target"
            )
        rows.setdefault(pid, (line, values))
    if columns is None:
        raise ProgramError(f"{path}: empty file (no header pose_id,cmd:<actuator>,...)")
    if not rows:
        raise ProgramError(f"{path}: no joint targets after the header")
    table = np.array([v for _, v in rows.values()])
    n_act = len(actuators)
    names = list(columns)[1 + n_act :]
    state = {c: table[:, n_act + i] for i, c in enumerate(names) if not c.startswith(DIR_PREFIX)}
    dirs = [n_act + i for i, c in enumerate(names) if c.startswith(DIR_PREFIX)]
    if dirs:
        d = table[:, dirs]
        if not np.all(np.isin(d, (-1.0, 0.0, 1.0))):
            raise ProgramError(f"{path}: the dir:<actuator> columns must be +1 or -1 (0: no move)")
        state["direction"] = d
    return Program(path, tuple(rows), table[:, :n_act] * scale, state)


def parse_seed(text: str, actuators: Sequence[str], is_slide: Sequence[bool]) -> np.ndarray:
    """Commands (A,) (SI) from a seed written ``A1=0,A2=-90,...`` (every actuator once, by
    name, mm or deg) or ``0,-90,...`` (one value per actuator, in the model's order)."""
    cells = [c.strip() for c in text.split(",")]
    shown = f"--seed {text!r}"
    if any("=" in c for c in cells):
        given: dict[str, str] = {}
        for cell in cells:
            name, sep, value = (s.strip() for s in cell.partition("="))
            if not sep:
                raise ProgramError(f"{shown}: '{cell}' is not NAME=VALUE (mix of forms)")
            if name not in actuators:
                raise ProgramError(
                    f"{shown}: '{name}' is no actuator of the model{closest(name, actuators)}; "
                    f"its actuators are {list(actuators)}"
                )
            if name in given:
                raise ProgramError(f"{shown}: '{name}' is given twice")
            given[name] = value
        missing = [a for a in actuators if a not in given]
        if missing:
            raise ProgramError(f"{shown}: no value for {missing}: give every actuator")
        values = [given[a] for a in actuators]
    else:
        if len(cells) != len(actuators):
            raise ProgramError(
                f"{shown}: {len(cells)} values for {len(actuators)} actuators {list(actuators)}"
            )
        values = cells
    out = []
    for name, value in zip(actuators, values, strict=True):
        try:
            v = float(value)
        except ValueError:
            raise ProgramError(f"{shown}: '{value}' ({name}) is not a number") from None
        if not math.isfinite(v):
            raise ProgramError(f"{shown}: '{value}' ({name}) is not finite")
        out.append(v)
    scale = np.where(np.asarray(is_slide, dtype=bool), 1e-3, math.pi / 180.0)
    return np.array(out) * scale
