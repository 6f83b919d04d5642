"""Scenario files: TOML a user can copy and edit, validated at load with errors that name the key.

A scenario names its ``study`` (the runner that wires truth twin -> dataset -> calib ->
compensation -> re-measure -> score), the model and error model, the truth, tracker and
pose plans. Paths inside are looked up beside the scenario file, then in the repository's
``scenarios/`` folder, then at the repository root. Lengths are millimetres and angles degrees,
converted to SI where they are read.

Each study declares the keys it reads (:data:`SCHEMAS`, with type and range); a file is
checked against its study's schema once, when it is loaded, before anything runs: an unknown
key, a value out of range, a misspelt effect argument or an unknown parameter in a values
file is a :class:`ScenarioError` naming the file and the dotted key as written in the file.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scenarios.config.keys import SCHEMAS
from scenarios.config.schema import (
    Key,
    ScenarioError,
    Table,
    name_problem,
    unknown_name_message,
    validate_table,
)
from twin.formats import read_utf8

REPO_ROOT = Path(__file__).resolve().parents[2]
SCENARIO_DIR = Path(__file__).resolve().parents[1]


def search_places(scenario_path: Path) -> list[Path]:
    """Where a relative path of a scenario is looked up: beside it, scenarios/, the repo."""
    places: list[Path] = []
    for base in (scenario_path.parent, SCENARIO_DIR, REPO_ROOT):
        if base not in places:
            places.append(base)
    return places


@dataclass(frozen=True)
class Scenario:
    name: str
    study: str
    path: Path
    data: dict[str, Any]
    schema: Table | None = field(default=None, compare=False, repr=False)

    def resolve(self, relative: str, key: str | None = None) -> Path:
        """A file named in the scenario: beside it, else in scenarios/, else the repo root."""
        what = f"'{key}': " if key else ""
        p = Path(relative)
        if p.is_absolute():
            if not p.exists():
                raise ScenarioError(f"{self.path}: {what}file '{relative}' not found")
            return p
        places = search_places(self.path)
        for base in places:
            if (base / p).exists():
                return base / p
        looked = ", ".join(str(base / p) for base in places)
        raise ScenarioError(f"{self.path}: {what}file '{relative}' not found; looked in {looked}")

    def section(self, key: str) -> dict[str, Any]:
        self._declared(key)
        value = self.data.get(key)
        if not isinstance(value, dict):
            raise ScenarioError(f"{self.path}: missing table [{key}]")
        return value

    def _declared(self, dotted: str) -> None:
        if self.schema is not None and self.schema.lookup(dotted) is None:
            # a programming error, not a user's: the study reads a key it does not declare
            raise LookupError(
                f"study '{self.study}' reads '{dotted}', which SCHEMAS['{self.study}'] "
                "does not declare"
            )

    def get(self, dotted: str, kind: type | tuple[type, ...], default: Any = ...) -> Any:
        """Value at ``a.b.c``; a missing key without default, or a wrong type, raises."""
        self._declared(dotted)
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
    """A scenario by name (scenarios/studies/<study>/<name>.toml) or by path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ScenarioError(f"scenario file not found: {p}")
        return p.resolve()
    found = [f for f in scenario_files() if f.stem == name_or_path]
    if not found:
        known = sorted(f.stem for f in scenario_files())
        raise ScenarioError(f"no scenario named '{name_or_path}'; known: {known}")
    return found[0]


def scenario_files() -> list[Path]:
    """The scenarios shipped with the project: scenarios/studies/<study>/<name>.toml."""
    return sorted(SCENARIO_DIR.glob("studies/*/*.toml"), key=lambda f: f.stem)


def _file_problems(scenario: Scenario, schema: Table) -> list[str]:
    """Every file the scenario names exists; a values file names only known parameters."""
    out = []
    for dotted in schema.leaf_names():
        spec = schema.lookup(dotted)
        if not (isinstance(spec, Key) and spec.path):
            continue
        node: Any = scenario.data
        for part in dotted.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        if node is None:
            continue
        try:
            scenario.resolve(node, dotted)
        except ScenarioError as exc:
            out.append(str(exc).removeprefix(f"{scenario.path}: "))
    values_file = scenario.data.get("truth", {}).get("values_file")
    if not out and values_file is not None:
        out += values_file_problems(
            scenario.resolve(values_file), scenario.resolve(scenario.data["error_model"])
        )
    return out


def _toml(path: Path) -> dict[str, Any] | None:
    try:
        return tomllib.loads(read_utf8(path))
    except (OSError, UnicodeError, tomllib.TOMLDecodeError):
        return None


def values_file_problems(values_path: Path, error_model_path: Path) -> list[str]:
    """Unknown parameter names of a ``[values]`` file against the error model's names.

    A file that cannot be read is left to the loaders, whose errors name it too."""
    values, model = _toml(values_path), _toml(error_model_path)
    if values is None or model is None or not isinstance(values.get("values"), dict):
        return []
    entries = model.get("parameter")
    if not isinstance(entries, list):
        return []
    names = [str(e["name"]) for e in entries if isinstance(e, dict) and "name" in e]
    return [
        f"{values_path}: [values] "
        + unknown_name_message("parameter", n, names)
        + f" (the parameters of {error_model_path.name})"
        for n in values["values"]
        if n not in names
    ]


def validate(scenario: Scenario, schema: Table) -> None:
    """Raise one ScenarioError listing every problem of the file against ``schema``."""
    problems = validate_table(scenario.data, schema, "", schema)
    if not problems:
        problems = _file_problems(scenario, schema)
    if len(problems) == 1:
        raise ScenarioError(f"{scenario.path}: {problems[0]}")
    if problems:
        listed = "\n".join(f"  - {p}" for p in problems)
        raise ScenarioError(f"{scenario.path}: {len(problems)} problems:\n{listed}")


def load_scenario(name_or_path: str) -> Scenario:
    """Read and validate a scenario against its study's schema; nothing runs before this."""
    path = find_scenario(name_or_path)
    try:
        data = tomllib.loads(read_utf8(path))  # UTF-8; a byte-order mark is accepted
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path} is not valid TOML: {exc}") from exc
    except (OSError, UnicodeError) as exc:
        raise ScenarioError(f"{path} cannot be read: {exc}") from exc
    study = data.get("study")
    if not isinstance(study, str):
        raise ScenarioError(f"{path}: missing 'study' (which runner to use)")
    if study not in SCHEMAS:
        raise ScenarioError(f"{path}: " + unknown_name_message("study", study, list(SCHEMAS)))
    name = data.get("name", path.stem)
    if not isinstance(name, str):
        raise ScenarioError(f"{path}: 'name' must be str, got {name!r}")
    if "name" not in data and (why := name_problem(name)) is not None:
        raise ScenarioError(
            f"{path}: the scenario's name (from the file name, no 'name' key) {why}, "
            f'got {name!r}; add name = "..."'
        )
    scenario = Scenario(name=name, study=study, path=path, data=data, schema=SCHEMAS[study])
    validate(scenario, SCHEMAS[study])
    return scenario
