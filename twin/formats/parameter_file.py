"""Error models and parameter values as TOML files a user can read and edit.

An error-model file lists ``[[parameter]]`` tables (``name``, ``kind``, ``element``, ``axis``);
a values file holds ``[values]`` by parameter name in millimetres and degrees (the units of
files; an ``actuator_gain``, whose element is an actuator's name and which needs no axis, in
ppm; a ``joint_compliance``, likewise an actuator's, in deg/(kN m) or mm/kN, with an optional
``payload_kg``: twin.parameter_kinds; the offset kinds with their constants, ``phase``,
``period_mm``, ``harmonic``, ``time_constant``, ``clock``, ``origin``: twin.offset_kinds),
converted to SI here and nowhere else.
"""

from __future__ import annotations

import difflib
import tomllib
from collections.abc import Iterable
from pathlib import Path

import mujoco
import numpy as np

from twin.exceptions import ParameterError
from twin.offset_kinds import CONSTANTS
from twin.parameters import KINDS, Parameter, ParameterSet

_BOMS = (  # longest first: the UTF-32 marks begin with the UTF-16 ones
    (b"\x00\x00\xfe\xff", "UTF-32 (big-endian)"),
    (b"\xff\xfe\x00\x00", "UTF-32 (little-endian)"),
    (b"\xfe\xff", "UTF-16 (big-endian)"),
    (b"\xff\xfe", "UTF-16 (little-endian)"),
)
ENTRY_FIELDS = ("name", "kind", "element", "axis", "payload_kg", *CONSTANTS)
REQUIRED_FIELDS = ("name", "kind", "element")
TOP_LEVEL_KEYS = ("model", "parameter")
_UTF8 = "UTF-8 is expected (save or export the file as UTF-8)"


def closest(word: str, choices: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices``, or an empty string."""
    near = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean {near[0]!r}?)" if near else ""


def _where(data: bytes, k: int) -> str:
    """Line and column (1-based, in bytes) of byte ``k``."""
    line = data.count(b"\n", 0, k) + 1
    column = k - (data.rfind(b"\n", 0, k) + 1) + 1
    return f"line {line}, column {column}"


def utf8_problem(data: bytes) -> str | None:
    """Why ``data`` is not UTF-8 text, naming the encoding it looks like; None if it is.

    A UTF-8 byte-order mark is accepted (decode with ``utf-8-sig``)."""
    for bom, name in _BOMS:
        if data.startswith(bom):
            return f"the file is {name} text (it starts with a byte-order mark); {_UTF8}"
    if b"\x00" in data:
        head = data[:4096]
        even, odd = head[0::2].count(0), head[1::2].count(0)
        if odd > 0.3 * len(head) / 2 and even < 0.05 * len(head) / 2:
            return f"the file looks like UTF-16 (little-endian) text (NUL bytes); {_UTF8}"
        if even > 0.3 * len(head) / 2 and odd < 0.05 * len(head) / 2:
            return f"the file looks like UTF-16 (big-endian) text (NUL bytes); {_UTF8}"
        k = data.index(b"\x00")
        return f"NUL byte at {_where(data, k)}: not a text file; {_UTF8}"
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        bad = data[exc.start : exc.start + 1]
        try:
            guess = f"; in Latin-1 / Windows-1252 it reads {bad.decode('cp1252')!r}"
        except UnicodeDecodeError:
            guess = ""
        return f"byte 0x{bad.hex()} at {_where(data, exc.start)} is not UTF-8{guess}; {_UTF8}"
    return None


def read_utf8(path: Path) -> str:
    """The text of ``path``; raises UnicodeError (its message names the cause) unless UTF-8."""
    data = path.read_bytes()
    problem = utf8_problem(data)
    if problem:
        raise UnicodeError(problem)
    return data.decode("utf-8-sig")


def _read_toml(path: Path) -> dict:
    if not path.is_file():
        raise ParameterError(f"parameter file not found: {path}")
    try:
        text = read_utf8(path)
    except UnicodeError as exc:
        raise ParameterError(f"{path}: {exc}") from None
    except OSError as exc:
        raise ParameterError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{path} is not valid TOML: {exc}") from exc


def _text_field(where: str, entry: dict, field: str) -> str:
    value = entry[field]
    if not isinstance(value, str) or not value.strip():
        raise ParameterError(
            f"{where}: field '{field}' must be a non-empty string, got {value!r} "
            f"({type(value).__name__})"
        )
    return value


def _axis_field(where: str, entry: dict) -> tuple[float, float, float]:
    raw = entry.get("axis", [0.0, 0.0, 0.0])
    if not isinstance(raw, list):
        raise ParameterError(
            f"{where}: field 'axis' must be an array of 3 numbers, got {raw!r} "
            f"({type(raw).__name__})"
        )
    if len(raw) != 3:
        raise ParameterError(
            f"{where} axis must have 3 components (field 'axis' has {len(raw)}: {raw!r})"
        )
    for i, x in enumerate(raw):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise ParameterError(
                f"{where}: field 'axis' component {i + 1} must be a number, got {x!r} "
                f"({type(x).__name__})"
            )
    return (float(raw[0]), float(raw[1]), float(raw[2]))


def _entry(path: Path, k: int, e: object) -> Parameter:
    """One ``[[parameter]]`` table as a Parameter; errors name the file, entry and field."""
    where = f"{path}: parameter #{k + 1}"
    if not isinstance(e, dict):
        raise ParameterError(
            f"{where} must be a table with fields {list(ENTRY_FIELDS)} (write [[parameter]] "
            f"sections), got {e!r} ({type(e).__name__})"
        )
    label = f" '{e['name']}'" if isinstance(e.get("name"), str) and e["name"] else ""
    where += label
    unknown = [f for f in e if f not in ENTRY_FIELDS]
    if unknown:
        f = unknown[0]
        raise ParameterError(
            f"{where}: unknown field '{f}'{closest(f, ENTRY_FIELDS)}; "
            f"the fields are {list(ENTRY_FIELDS)}"
        )
    missing = [f for f in REQUIRED_FIELDS if f not in e]
    if missing:
        named = f" (name{label})" if label else ""
        raise ParameterError(f"{path}: parameter #{k + 1} lacks {missing}{named}")
    name, kind, element = (_text_field(where, e, f) for f in REQUIRED_FIELDS)
    if kind not in KINDS:
        raise ParameterError(
            f"{where}: field 'kind' is '{kind}'{closest(kind, KINDS)}; the kinds are {list(KINDS)}"
        )
    axis = _axis_field(where, e)
    try:
        consts = {c: e[c] for c in CONSTANTS if c in e}
        return Parameter(name, kind, element, axis, e.get("payload_kg"), consts)
    except ParameterError as exc:
        raise ParameterError(f"{path}: parameter #{k + 1}: {exc}") from None


def load_parameter_set(path: str | Path, model: mujoco.MjModel) -> ParameterSet:
    """Read an error model and bind it to ``model`` (errors name the file, entry and field)."""
    path = Path(path)
    doc = _read_toml(path)
    unknown = [key for key in doc if key not in TOP_LEVEL_KEYS]
    if unknown:
        key = unknown[0]
        raise ParameterError(
            f"{path}: unknown top-level key '{key}'{closest(key, TOP_LEVEL_KEYS)}; "
            f"an error model has {list(TOP_LEVEL_KEYS)}"
        )
    if "model" in doc and not isinstance(doc["model"], str):
        raise ParameterError(f"{path}: 'model' must be a string, got {doc['model']!r}")
    machine = model.names[: model.names.find(b"\0")].decode()
    if "model" in doc and machine and doc["model"] != machine:
        raise ParameterError(
            f"{path} is an error model for '{doc['model']}', but the MJCF is '{machine}' "
            "(its <mujoco model=...>): another machine's errors"
        )
    entries = doc.get("parameter")
    if entries is None or entries == []:
        raise ParameterError(f"{path} has no [[parameter]] entries")
    if not isinstance(entries, list):
        raise ParameterError(
            f"{path}: 'parameter' must be an array of tables ([[parameter]] sections), "
            f"got {entries!r} ({type(entries).__name__})"
        )
    params = [_entry(path, k, e) for k, e in enumerate(entries)]
    try:
        return ParameterSet(params, model)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None


def values_from_display(
    params: ParameterSet, display: dict[str, float], source: str = "values"
) -> np.ndarray:
    """SI vector from a {name: mm, deg or ppm} mapping; names not given are zero, unknown ones
    fail."""
    unknown = sorted(set(display) - set(params.names))
    if unknown:
        raise ParameterError(f"{source}: unknown parameter names {unknown}")
    shown = np.zeros(len(params))
    for name, v in display.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ParameterError(f"{source}: value of '{name}' must be a number, got {v!r}")
        if not np.isfinite(float(v)):
            raise ParameterError(f"{source}: value of '{name}' is not finite")
        shown[params.index(name)] = float(v)
    return params.from_display(shown)


def load_values(path: str | Path, params: ParameterSet) -> np.ndarray:
    """Parameter values (SI) from a ``[values]`` file in mm, deg and ppm."""
    path = Path(path)
    doc = _read_toml(path)
    if doc.get("unit", "mm") != "mm":
        raise ParameterError(
            f"{path}: unit must be 'mm' (angles in deg, gains in ppm), got {doc.get('unit')!r}"
        )
    values = doc.get("values")
    if not isinstance(values, dict):
        raise ParameterError(f"{path} has no [values] table")
    return values_from_display(params, values, source=str(path))
