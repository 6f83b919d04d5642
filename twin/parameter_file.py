"""Error models and parameter values as TOML files a user can read and edit.

An error-model file lists ``[[parameter]]`` tables (``name``, ``kind``, ``element``, ``axis``);
a values file holds ``[values]`` by parameter name in millimetres and degrees (the units of
files), converted to SI here and nowhere else.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import mujoco
import numpy as np

from twin.exceptions import ParameterError
from twin.parameters import Parameter, ParameterSet


def _read_toml(path: Path) -> dict:
    if not path.is_file():
        raise ParameterError(f"parameter file not found: {path}")
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{path} is not valid TOML: {exc}") from exc


def load_parameter_set(path: str | Path, model: mujoco.MjModel) -> ParameterSet:
    """Read an error model and bind it to ``model`` (errors name the file and entry)."""
    path = Path(path)
    doc = _read_toml(path)
    entries = doc.get("parameter")
    if not isinstance(entries, list) or not entries:
        raise ParameterError(f"{path} has no [[parameter]] entries")
    params = []
    for k, e in enumerate(entries):
        missing = [f for f in ("name", "kind", "element") if f not in e]
        if missing:
            raise ParameterError(f"{path}: parameter #{k + 1} lacks {missing}")
        raw = e.get("axis", (0.0, 0.0, 0.0))
        try:
            axis = tuple(float(x) for x in raw)
        except (TypeError, ValueError):
            raise ParameterError(
                f"{path}: parameter '{e['name']}' axis must be 3 numbers, got {raw!r}"
            ) from None
        if len(axis) != 3:
            raise ParameterError(f"{path}: parameter '{e['name']}' axis must have 3 components")
        params.append(Parameter(str(e["name"]), str(e["kind"]), str(e["element"]), axis))
    return ParameterSet(params, model)


def values_from_display(
    params: ParameterSet, display: dict[str, float], source: str = "values"
) -> np.ndarray:
    """SI vector from a {name: mm-or-deg} mapping; names not given are zero, unknown ones fail."""
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
    """Parameter values (SI) from a ``[values]`` file in mm and deg."""
    path = Path(path)
    doc = _read_toml(path)
    if doc.get("unit", "mm") != "mm":
        raise ParameterError(f"{path}: unit must be 'mm' (angles in deg), got {doc.get('unit')!r}")
    values = doc.get("values")
    if not isinstance(values, dict):
        raise ParameterError(f"{path} has no [values] table")
    return values_from_display(params, values, source=str(path))
