"""Scenario files: TOML a user can copy and edit, loaded with errors that name the key.

A scenario names its ``study`` (the runner that wires truth twin -> dataset -> calib ->
compensation -> re-measure -> score), the model and error model, the truth, tracker and
pose plans. Paths inside are relative to the scenario file, else to the repository root.
Lengths are millimetres and angles degrees, converted to SI where they are read.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parent.parent
SCENARIO_DIR = Path(__file__).resolve().parent


class ScenarioError(ValueError):
    """A scenario file that is missing, malformed, or asks for something unknown."""


@dataclass(frozen=True)
class Scenario:
    name: str
    study: str
    path: Path
    data: dict[str, Any]

    def resolve(self, relative: str) -> Path:
        """A path from the file: relative to the scenario's folder, else the repo root."""
        p = Path(relative)
        if p.is_absolute():
            if not p.exists():
                raise ScenarioError(f"{self.path}: file '{relative}' not found")
            return p
        for base in (self.path.parent, REPO_ROOT):
            if (base / p).exists():
                return base / p
        raise ScenarioError(
            f"{self.path}: file '{relative}' not found (looked beside it and in {REPO_ROOT})"
        )

    def section(self, key: str) -> dict[str, Any]:
        value = self.data.get(key)
        if not isinstance(value, dict):
            raise ScenarioError(f"{self.path}: missing table [{key}]")
        return value

    def get(self, dotted: str, kind: type | tuple[type, ...], default: Any = ...) -> Any:
        """Value at ``a.b.c``; a missing key without default, or a wrong type, raises."""
        node: Any = self.data
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                if default is ...:
                    raise ScenarioError(f"{self.path}: missing key '{dotted}'")
                return default
            node = node[part]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if float in kinds and isinstance(node, int) and not isinstance(node, bool):
            node = float(node)
        if not isinstance(node, kinds) or (isinstance(node, bool) and bool not in kinds):
            names = "/".join(k.__name__ for k in kinds)
            raise ScenarioError(f"{self.path}: '{dotted}' must be {names}, got {node!r}")
        return node


def find_scenario(name_or_path: str) -> Path:
    """A scenario by name (scenarios/<name>.toml) or by path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ScenarioError(f"scenario file not found: {p}")
        return p.resolve()
    candidate = SCENARIO_DIR / f"{name_or_path}.toml"
    if not candidate.is_file():
        known = sorted(f.stem for f in SCENARIO_DIR.glob("*.toml"))
        raise ScenarioError(f"no scenario named '{name_or_path}'; known: {known}")
    return candidate


def load_scenario(name_or_path: str) -> Scenario:
    path = find_scenario(name_or_path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path} is not valid TOML: {exc}") from exc
    study = data.get("study")
    if not isinstance(study, str):
        raise ScenarioError(f"{path}: missing 'study' (which runner to use)")
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name or "/" in name:
        raise ScenarioError(f"{path}: 'name' must be a plain non-empty string")
    return Scenario(name=name, study=study, path=path, data=data)
