"""CSV + JSON sidecar reading and writing for :mod:`calib.data.dataset`.

File units are millimetres and degrees; the returned :class:`~calib.data.dataset.Dataset`
is SI. Both files are written as one set (:mod:`common.write_set`: both or neither), with the
mode of an ordinary file (0644 less the umask). Both are read as UTF-8 (a UTF-8 byte-order
mark is accepted); another encoding, another delimiter than ',' or a malformed cell raises
:class:`~calib.data.dataset.DatasetError` naming the file, line and column.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from calib.data.dataset import (
    ACTUATOR_UNITS,
    FORMAT,
    VERSION,
    Dataset,
    DatasetError,
    check_names,
    sidecar_path,
)
from calib.data.orientation_columns import QUAT_COLUMNS, parse_quaternion, refuse_rotation_columns
from common.write_set import write_files
from twin.formats.parameter_file import closest, read_utf8

CMD_PREFIX = "cmd:"
DIR_PREFIX = "dir:"  # each actuator's approach direction, +1/-1 (all actuators or none)
REQUIRED_COLUMNS = ("pose_id", "set", "target", "repeat", "x_mm", "y_mm", "z_mm")
OPTIONAL_COLUMNS = ("order", "time_s", "temperature_c")
POSE_COLUMNS = ("pose_x_mm", "pose_y_mm", "pose_z_mm", "pose_rx_deg", "pose_ry_deg", "pose_rz_deg")
INT64 = (-(2**63), 2**63 - 1)  # pose_id, repeat and order are stored as int64
# No laser tracker or motion-capture system measures a machine from a kilometre away (trackers
# reach 80-160 m): a reading beyond it is an export error (and its square overflows the fit)
MAX_READING_MM = 1e6
_SIDECAR_REQUIRED = ("format", "version", "model", "frame", "length_unit", "angle_unit")
_SIDECAR_KEYS = {*_SIDECAR_REQUIRED, "actuators", "targets", "notes", "tracker", "meta"}


def _si_commands(values: np.ndarray, units: Sequence[str]) -> np.ndarray:
    mm = np.array([u == "mm" for u in units])
    return np.where(mm, values / 1000.0, np.deg2rad(values))


def _file_commands(values: np.ndarray, units: Sequence[str]) -> np.ndarray:
    mm = np.array([u == "mm" for u in units])
    return np.where(mm, values * 1000.0, np.rad2deg(values))


def _fmt(value: float) -> str:
    return repr(float(value))  # shortest string that round-trips float64


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def write_csv_dataset(dataset: Dataset, csv_path: str | os.PathLike[str]) -> Path:
    """Implementation of :func:`calib.data.dataset.write_dataset`."""
    ds, path = dataset, Path(csv_path)
    cmd_cols = [CMD_PREFIX + a for a in ds.actuator_names]
    header = ["pose_id", "set", "target", "repeat"]
    header += [c for c in OPTIONAL_COLUMNS if getattr(ds, c) is not None]
    dir_cols = [] if ds.direction is None else [DIR_PREFIX + a for a in ds.actuator_names]
    header += cmd_cols + dir_cols
    header += list(POSE_COLUMNS) if ds.commanded_poses is not None else []
    header += ["x_mm", "y_mm", "z_mm"] + (list(QUAT_COLUMNS) if ds.orientations is not None else [])
    commands = _file_commands(ds.commands, ds.actuator_units)
    points = ds.readings * 1000.0
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for p in range(ds.n_poses):
        per_pose = [_fmt(v) for v in commands[p]]
        if ds.direction is not None:
            per_pose += [str(int(v)) for v in ds.direction[p]]
        if ds.commanded_poses is not None:
            cp = ds.commanded_poses[p]
            per_pose += [_fmt(v) for v in (*(cp[:3] * 1000.0), *np.rad2deg(cp[3:]))]
        extra = [] if ds.order is None else [str(int(ds.order[p]))]
        extra += [] if ds.time_s is None else [_fmt(ds.time_s[p])]
        extra += [] if ds.temperature_c is None else [_fmt(ds.temperature_c[p])]
        for t, target in enumerate(ds.target_names):
            for r in range(ds.n_repeats):
                xyz = [_fmt(v) for v in points[p, t, r]]
                if ds.orientations is not None:
                    q = ds.orientations[p, t, r]
                    xyz += [_fmt(v) for v in q] if np.isfinite(q).all() else [""] * 4
                row = [str(int(ds.pose_ids[p])), ds.sets[p], target, str(r), *extra]
                writer.writerow([*row, *per_pose, *xyz])
    sidecar: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "model": ds.model,
        "frame": ds.frame,
        "length_unit": "mm",
        "angle_unit": "deg",
        "actuators": dict(zip(ds.actuator_names, ds.actuator_units, strict=True)),
        "targets": list(ds.target_names),
        "notes": ds.notes,
    }
    for key in ("tracker", "meta"):
        if getattr(ds, key) is not None:
            sidecar[key] = getattr(ds, key)
    text = json.dumps(sidecar, indent=2, ensure_ascii=False, allow_nan=False, default=_json_default)
    write_files({path: buf.getvalue(), sidecar_path(path): text + "\n"})  # both, or neither
    return path


_DELIMITERS = {";": "';'", "\t": "tab ('\\t')", "|": "'|'"}


def _read_text(path: Path, what: str) -> str:
    """The UTF-8 text of a dataset file (a UTF-8 byte-order mark is accepted)."""
    try:
        return read_utf8(path)
    except UnicodeError as exc:
        raise DatasetError(f"{path}: cannot read the {what}: {exc}") from None
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None


def _other_delimiter(fields: Sequence[str]) -> str | None:
    """The delimiter a line split on commas into ``fields`` seems to use instead, if any."""
    if len(fields) != 1:
        return None
    counts = {d: fields[0].count(d) for d in _DELIMITERS}
    best = max(counts, key=lambda d: counts[d])
    return best if counts[best] else None


def _delimiter_message(delimiter: str) -> str:
    return (
        f"the file uses {_DELIMITERS[delimiter]} as delimiter; the format is comma-separated "
        "(fields separated by ',', '.' as decimal point)"
    )


def _read_sidecar(path: Path) -> dict[str, Any]:
    if not path.exists():
        raise DatasetError(f"{path}: sidecar file not found (expected '<csv path>.json')")
    text = _read_text(path, "sidecar")
    if not text.strip():
        raise DatasetError(f"{path}: empty sidecar file (expected a JSON object)")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DatasetError(
            f"{path}: malformed JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from None
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: the sidecar must be a JSON object")
    if data.get("format") != FORMAT:
        raise DatasetError(f"{path}: format is {data.get('format')!r}, expected {FORMAT!r}")
    if type(data.get("version")) is not int or data["version"] != VERSION:
        raise DatasetError(f"{path}: unsupported version {data.get('version')!r} ({VERSION} only)")
    missing = [k for k in (*_SIDECAR_REQUIRED, "actuators", "targets") if k not in data]
    unknown = sorted(set(data) - _SIDECAR_KEYS)
    if missing or unknown:
        hints = "".join(f"; {k!r}{closest(k, _SIDECAR_KEYS - set(data))}" for k in unknown)
        raise DatasetError(f"{path}: missing keys {missing}, unknown keys {unknown}{hints}")
    for key, want in (("length_unit", "mm"), ("angle_unit", "deg")):
        if data[key] != want:
            raise DatasetError(f"{path}: {key} is {data[key]!r}, expected {want!r}")
    for key in ("model", "frame"):
        if not isinstance(data[key], str) or not data[key]:
            raise DatasetError(f"{path}: {key!r} must be a non-empty string")
    acts = data["actuators"]
    if not isinstance(acts, dict) or not acts:
        raise DatasetError(f"{path}: 'actuators' must be a non-empty object name -> unit")
    for name, unit in acts.items():
        if unit not in ACTUATOR_UNITS:
            raise DatasetError(
                f"{path}: actuator {name!r} has unit {unit!r}, expected 'mm' or 'deg'"
            )
    if not isinstance(data["targets"], list):
        raise DatasetError(f"{path}: 'targets' must be a list of names")
    for key, kind in (("tracker", dict), ("meta", dict), ("notes", str)):
        if data.get(key) is not None and not isinstance(data[key], kind):
            raise DatasetError(f"{path}: {key!r} must be a JSON {kind.__name__}")
    try:
        check_names(acts, "actuator")
        check_names(data["targets"], "target")
    except DatasetError as exc:
        raise DatasetError(f"{path}: {exc}") from None
    return data


def _columns(path: Path, header: list[str], actuators: Sequence[str]) -> dict[str, int]:
    refuse_rotation_columns(path, header)
    dups = sorted({h for h in header if header.count(h) > 1})
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    no_cmd = [a for a in actuators if CMD_PREFIX + a not in header]
    declared = {CMD_PREFIX + a for a in actuators}
    undeclared = [h for h in header if h.startswith(CMD_PREFIX) and h not in declared]
    pose = [c for c in POSE_COLUMNS if c in header]
    dirs = {DIR_PREFIX + a for a in actuators}
    dir_given = [h for h in header if h.startswith(DIR_PREFIX)]
    known = {*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS, *POSE_COLUMNS, *QUAT_COLUMNS, *declared, *dirs}
    unknown = [h for h in header if h not in known and h not in undeclared]
    if not set(header) & ({*known, *undeclared} - set(OPTIONAL_COLUMNS)):
        shown = ",".join(header)
        shown = shown if len(shown) <= 60 else shown[:57] + "..."
        raise DatasetError(
            f"{path}: not a dataset CSV: its first line {shown!r} names none of the columns "
            f"of the format ({', '.join(REQUIRED_COLUMNS)}, cmd:<actuator> ...)"
        )
    for bad, what in (
        (dups, "duplicate column(s)"),
        (missing, "missing required column(s)"),
        (no_cmd, "actuator(s) declared in the sidecar without a 'cmd:<name>' column"),
        (undeclared, "column(s) for actuators not declared in the sidecar"),
        ([c for c in POSE_COLUMNS if pose and c not in pose], "missing commanded-pose column(s)"),
        (
            sorted(dirs - set(dir_given)) if dir_given else [],
            "missing approach-direction column(s) (dir:<actuator> for every actuator or none)",
        ),
        (unknown, "unknown column(s)"),
    ):
        if bad:
            raise DatasetError(f"{path}: {what}: {bad}")
    return {h: i for i, h in enumerate(header)}


def _number(loc: str, column: str, text: str, integer: bool = False) -> float:
    try:
        if "_" in text:  # Python would read "1_000" as 1000: not a number in a CSV file
            raise ValueError(text)
        value = int(text) if integer else float(text)
    except ValueError:
        kind = "an integer" if integer else "a number"
        raise DatasetError(f"{loc}, column {column!r}: expected {kind}, got {text!r}") from None
    if not math.isfinite(value):
        raise DatasetError(f"{loc}, column {column!r}: non-finite value {text!r}")
    if integer and not INT64[0] <= value <= INT64[1]:
        raise DatasetError(
            f"{loc}, column {column!r}: {text} is outside the range of a 64-bit integer "
            f"[{INT64[0]}, {INT64[1]}]"
        )
    if column.endswith("_mm") and abs(value) > MAX_READING_MM:
        raise DatasetError(
            f"{loc}, column {column!r}: {value:g} mm is beyond {MAX_READING_MM:g} mm (1 km), "
            "no reading of a machine; check the export"
        )
    return value


# Per pose: line of its first row, values that must agree across its rows, and
# the measured points keyed by (target index, repeat).
_Pose = tuple[int, list[Any], dict[tuple[int, int], list[float]]]


def _group_rows(
    path: Path,
    rows: list[tuple[int, list[str]]],
    col: dict[str, int],
    pose_cols: list[str],
    targets: list[str],
) -> dict[int, _Pose]:
    """Parse data rows and group them by pose_id in order of first appearance."""
    poses: dict[int, _Pose] = {}
    seen: dict[tuple[int, str, int], int] = {}
    for n, (line, row) in enumerate(rows, start=1):
        loc = f"{path} line {line} (data row {n})"
        if len(row) != len(col):
            delimiter = _other_delimiter(row)
            hint = "" if delimiter is None else f" ({_delimiter_message(delimiter)})"
            raise DatasetError(f"{loc}: {len(row)} fields, the header has {len(col)}{hint}")
        cell = {h: row[i].strip() for h, i in col.items()}
        pid = int(_number(loc, "pose_id", cell["pose_id"], integer=True))
        rep = int(_number(loc, "repeat", cell["repeat"], integer=True))
        target = cell["target"]
        if target not in targets:
            raise DatasetError(f"{loc}: target {target!r} is not declared in the sidecar")
        if rep < 0:
            raise DatasetError(f"{loc}, column 'repeat': negative repeat {rep}")
        if (pid, target, rep) in seen:
            raise DatasetError(
                f"{loc}: duplicate row for pose {pid}, target {target!r}, repeat {rep} "
                f"(first at line {seen[pid, target, rep]})"
            )
        seen[pid, target, rep] = line
        if not cell["set"]:
            raise DatasetError(f"{loc}, column 'set': empty set name")
        values = [cell["set"]]
        values += [_number(loc, c, cell[c], integer=c == "order") for c in pose_cols[1:]]
        xyz = [_number(loc, c, cell[c]) for c in ("x_mm", "y_mm", "z_mm")]
        if "qw" in cell:  # NaN where the target has no orientation
            xyz += parse_quaternion(loc, [cell[c] for c in QUAT_COLUMNS]) or [math.nan] * 4
        first_line, first, points = poses.setdefault(pid, (line, values, {}))
        for c, old, new in zip(pose_cols, first, values, strict=True):
            if old != new:
                what = f"actuator {c[len(CMD_PREFIX) :]!r}" if c.startswith(CMD_PREFIX) else c
                raise DatasetError(
                    f"{loc}: inconsistent {what} (column {c!r}) for pose {pid}: "
                    f"{new!r} here, {old!r} at line {first_line}"
                )
        points[targets.index(target), rep] = xyz
    return poses


def _n_repeats(path: Path, poses: dict[int, _Pose], targets: list[str]) -> int:
    """Number of repeats; raises unless every pose has every target and repeat."""
    n_rep = 1 + max(r for _, _, points in poses.values() for _, r in points)
    for pid, (_, _, points) in poses.items():
        for t, target in enumerate(targets):
            got = {r for (ti, r) in points if ti == t}
            if not got:
                raise DatasetError(f"{path}: pose {pid} has no rows for target {target!r}")
            if len(got) != n_rep:
                raise DatasetError(
                    f"{path}: pose {pid}, target {target!r} is missing repeat(s) "
                    f"{sorted(set(range(n_rep)) - got)} (other rows have repeats 0..{n_rep - 1})"
                )
    return n_rep


def require_model(csv_path: str | os.PathLike[str], model: str, expected_model: str) -> None:
    """Raise DatasetError unless the dataset at ``csv_path``, of ``model`` (its sidecar's),
    is of ``expected_model``: what :func:`read_dataset` checks of a file read before the
    model was known."""
    if model != expected_model:
        raise DatasetError(
            f"{sidecar_path(Path(csv_path))}: model is {model!r}, expected {expected_model!r} "
            "(the model's own name: a model made by pkm-calib from-urdf takes the URDF's robot "
            f"name; regenerate it with --name {model}, or correct the sidecar's "
            "'model' if the readings are of this machine)"
        )


def read_csv_dataset(
    csv_path: str | os.PathLike[str], expected_model: str | None = None
) -> Dataset:
    """Implementation of :func:`calib.data.dataset.read_dataset`."""
    path = Path(csv_path)
    if not path.is_file():
        raise DatasetError(f"{path}: dataset CSV file not found")
    side = _read_sidecar(sidecar_path(path))
    if expected_model is not None:
        require_model(path, side["model"], expected_model)
    acts, targets = list(side["actuators"]), list(side["targets"])
    reader = csv.reader(io.StringIO(_read_text(path, "dataset CSV"), newline=""))
    try:
        header: list[str] = []
        for first in reader:  # the first line that is not blank
            header = [h.strip() for h in first]
            if any(header):
                break
        if not any(header):
            raise DatasetError(f"{path}: empty file (no header and no data rows)")
        delimiter = _other_delimiter(header)
        if delimiter is not None and set(header[0].split(delimiter)) & set(REQUIRED_COLUMNS):
            raise DatasetError(f"{path} line {reader.line_num}: {_delimiter_message(delimiter)}")
        col = _columns(path, header, acts)
        rows = [(reader.line_num, r) for r in reader if any(c.strip() for c in r)]
    except csv.Error as exc:
        raise DatasetError(f"{path} line {reader.line_num}: not readable as CSV: {exc}") from None
    if not rows:
        raise DatasetError(f"{path}: no data rows")
    pose_cols = ["set", *(CMD_PREFIX + a for a in acts)]
    pose_cols += [c for c in (*OPTIONAL_COLUMNS, *POSE_COLUMNS) if c in col]
    pose_cols += [DIR_PREFIX + a for a in acts if DIR_PREFIX + a in col]
    poses = _group_rows(path, rows, col, pose_cols, targets)
    n_rep = _n_repeats(path, poses, targets)
    recs = list(poses.values())
    table = np.array([vals[1:] for _, vals, _ in recs], dtype=float).reshape(len(recs), -1)
    units = [side["actuators"][a] for a in acts]
    opt = {c: table[:, i] for i, c in enumerate(pose_cols[1:]) if not c.startswith(CMD_PREFIX)}
    dirs = [opt.pop(DIR_PREFIX + a) for a in acts if DIR_PREFIX + a in opt]
    cposes = None
    if "pose_x_mm" in opt:
        cposes = np.stack([opt[c] for c in POSE_COLUMNS], axis=1)
        cposes = np.concatenate([cposes[:, :3] / 1000.0, np.deg2rad(cposes[:, 3:])], axis=1)
    readings = np.array(
        [[[pts[t, r] for r in range(n_rep)] for t in range(len(targets))] for _, _, pts in recs]
    )
    quats = readings[..., 3:] if "qw" in col else None
    try:
        return Dataset(
            model=side["model"],
            frame=side["frame"],
            actuator_names=tuple(acts),
            actuator_units=tuple(units),
            target_names=tuple(targets),
            pose_ids=np.array(list(poses), dtype=np.int64),
            sets=np.array([vals[0] for _, vals, _ in recs]),
            commands=_si_commands(table[:, : len(acts)], units),
            readings=readings[..., :3] / 1000.0,
            orientations=quats,
            order=opt["order"].astype(np.int64) if "order" in opt else None,
            time_s=opt.get("time_s"),
            temperature_c=opt.get("temperature_c"),
            direction=np.stack(dirs, axis=1) if dirs else None,
            commanded_poses=cposes,
            tracker=side.get("tracker"),
            meta=side.get("meta"),
            notes=side.get("notes") or "",
        )
    except DatasetError as exc:
        raise DatasetError(f"{path}: {exc}") from None


def write_dataset(dataset: Dataset, csv_path: str | os.PathLike[str]) -> Path:
    """Write the CSV and its sidecar atomically; rows ordered by pose, target, repeat."""
    return write_csv_dataset(dataset, csv_path)


def read_dataset(csv_path: str | os.PathLike[str], expected_model: str | None = None) -> Dataset:
    """Read and validate a CSV dataset and its sidecar; values are converted to SI."""
    return read_csv_dataset(csv_path, expected_model)
