"""The vocabulary of scenario files: keys and tables with their types and ranges, checked
with errors that name the key, and the checks of effects, estimators and truths."""

from __future__ import annotations

import difflib
import inspect
import re
import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from scenarios.config.effects import EFFECT_EXCLUDED_ARGS, EFFECTS


class ScenarioError(ValueError):
    """A scenario file that is missing, malformed, or asks for something unknown."""


# ----------------------------------------------------------------------------- the schema


@dataclass(frozen=True)
class Key:
    """One value of a scenario file: its type, whether it must be given, and its range.

    ``kind`` is ``int``, ``float`` (an integer is accepted), ``str``, ``bool`` or ``list``.
    The bounds apply to a number, or to each number of a list; ``item`` is the type of a
    list's entries (``float``, ``int``, ``str`` or a :class:`Table` for an array of tables).
    ``path`` marks a file name, which must exist (see :func:`search_places`). ``check`` gets
    the value and its dotted key and returns problems (messages without the file name)."""

    kind: type
    required: bool = False
    min: float | None = None
    above: float | None = None
    max: float | None = None
    below: float | None = None
    choices: tuple[str, ...] | None = None
    item: type | Table | None = None
    length: int | None = None
    min_items: int | None = None
    path: bool = False
    check: Callable[[Any, str], list[str]] | None = None


@dataclass(frozen=True)
class Table:
    """A TOML table: its keys (values or nested tables), and whether it must be present."""

    keys: dict[str, Key | Table]
    required: bool = False
    check: Callable[[dict[str, Any], str], list[str]] | None = None

    def leaf_names(self, prefix: str = "") -> list[str]:
        """Every dotted key below this table (values and tables)."""
        out = []
        for k, v in self.keys.items():
            dotted = f"{prefix}{k}"
            out.append(dotted)
            if isinstance(v, Table):
                out.extend(v.leaf_names(f"{dotted}."))
        return out

    def lookup(self, dotted: str) -> Key | Table | None:
        node: Key | Table = self
        for part in dotted.split("."):
            if not isinstance(node, Table) or part not in node.keys:
                return None
            node = node.keys[part]
        return node


_KIND_NAMES = {int: "int", float: "float", str: "str", bool: "bool", list: "list", dict: "table"}


def _kind_name(kind: Any) -> str:
    if isinstance(kind, Table):
        return "table"
    return _KIND_NAMES.get(kind, getattr(kind, "__name__", str(kind)))


def _is_kind(value: Any, kind: Any) -> bool:
    if isinstance(kind, Table) or kind is dict:
        return isinstance(value, dict)
    if kind is bool:
        return isinstance(value, bool)
    if isinstance(value, bool):
        return False
    if kind is float:
        return isinstance(value, (int, float))
    return isinstance(value, kind)


def _range_problems(value: float, key: Key, where: str) -> list[str]:
    if isinstance(value, float) and value != value:
        return [f"'{where}' must be a number, got nan"]
    out = []
    if key.min is not None and not value >= key.min:
        out.append(f"'{where}' must be >= {key.min:g}, got {value!r}")
    if key.above is not None and not value > key.above:
        out.append(f"'{where}' must be > {key.above:g}, got {value!r}")
    if key.max is not None and not value <= key.max:
        out.append(f"'{where}' must be <= {key.max:g}, got {value!r}")
    if key.below is not None and not value < key.below:
        out.append(f"'{where}' must be < {key.below:g}, got {value!r}")
    if value in (float("inf"), float("-inf")):
        out.append(f"'{where}' must be finite, got {value!r}")
    return out


def _closest(word: str, candidates: list[str]) -> str | None:
    match = difflib.get_close_matches(word, candidates, n=1, cutoff=0.6)
    return match[0] if match else None


def unknown_name_message(what: str, name: str, known: list[str]) -> str:
    """``unknown <what> 'x'; did you mean 'y'?`` (or the known names when none is close)."""
    best = _closest(name, known)
    hint = f"did you mean '{best}'?" if best else f"known: {', '.join(sorted(known))}"
    return f"unknown {what} '{name}'; {hint}"


def _unknown_key(key: str, where: str, table: Table, root: Table) -> str:
    dotted = f"{where}.{key}" if where else key
    siblings = list(table.keys)
    best = _closest(key, siblings)
    if best is not None:
        full = f"{where}.{best}" if where else best
        return f"unknown key '{dotted}'; did you mean '{full}'?"
    # the right name in the wrong table, e.g. sigma_mm at the top instead of in [tracker]
    elsewhere = [d for d in root.leaf_names() if d.rsplit(".", 1)[-1] == key and d != dotted]
    if elsewhere:
        return f"unknown key '{dotted}'; did you mean '{elsewhere[0]}'?"
    known = ", ".join(f"'{f'{where}.{s}' if where else s}'" for s in siblings)
    return f"unknown key '{dotted}'; known keys here: {known}"


def validate_value(value: Any, key: Key, where: str, root: Table) -> list[str]:
    """Problems with one value (type, range, list entries, its own check)."""
    if not _is_kind(value, key.kind):
        return [f"'{where}' must be {_kind_name(key.kind)}, got {value!r}"]
    out: list[str] = []
    if key.choices is not None and value not in key.choices:
        best = _closest(str(value), list(key.choices))
        hint = f"; did you mean '{best}'?" if best else ""
        out.append(f"'{where}' must be one of {list(key.choices)}, got {value!r}{hint}")
    if key.kind in (int, float):
        out += _range_problems(value, key, where)
    if key.kind is list:
        if key.length is not None and len(value) != key.length:
            out.append(f"'{where}' must have {key.length} entries, got {len(value)}")
        if key.min_items is not None and len(value) < key.min_items:
            out.append(f"'{where}' must have at least {key.min_items} entries, got {len(value)}")
        if key.item is not None:
            for i, v in enumerate(value):
                at = f"{where}[{i}]"
                if isinstance(key.item, Table):
                    if not isinstance(v, dict):
                        out.append(f"'{at}' must be a table, got {v!r}")
                    else:
                        out += validate_table(v, key.item, at, key.item)
                elif not _is_kind(v, key.item):
                    out.append(f"'{at}' must be {_kind_name(key.item)}, got {v!r}")
                elif key.item in (int, float):
                    out += _range_problems(v, key, at)
    if not out and key.check is not None:
        out += key.check(value, where)
    return out


def validate_table(data: dict[str, Any], table: Table, where: str, root: Table) -> list[str]:
    """Problems with a table: unknown keys (with the closest known), missing, bad values."""
    out: list[str] = []
    for k in data:
        if k not in table.keys:
            out.append(_unknown_key(k, where, table, root))
    for k, spec in table.keys.items():
        dotted = f"{where}.{k}" if where else k
        if k not in data:
            if spec.required:
                out.append(
                    f"missing table [{dotted}]"
                    if isinstance(spec, Table)
                    else f"missing key '{dotted}'"
                )
            continue
        value = data[k]
        if isinstance(spec, Table):
            if not isinstance(value, dict):
                out.append(f"'{dotted}' must be a table ([{dotted}]), got {value!r}")
            else:
                out += validate_table(value, spec, dotted, root)
        else:
            out += validate_value(value, spec, dotted, root)
    if not out and table.check is not None:
        out += table.check(data, where)
    return out


# ------------------------------------------------------------------ checks of single values

_PLAIN_NAME = re.compile(r"[A-Za-z0-9_.-]+")


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a results folder (None if it can)."""
    if not name:
        return "must not be empty"
    if not _PLAIN_NAME.fullmatch(name):
        return "may hold only letters, digits, '_', '-' and '.' (no path separators or spaces)"
    if name in (".", ".."):
        return "must not be '.' or '..'"
    if name.startswith("."):
        return "must not start with '.' (hidden and temporary folders do)"
    return None


def _check_name(value: str, where: str) -> list[str]:
    why = name_problem(value)
    return [] if why is None else [f"'{where}' {why}, got {value!r}"]


def _check_noise_spec(value: str, where: str) -> list[str]:
    from twin.tracker import TrackerNoise

    try:
        TrackerNoise.from_spec(value)
    except ValueError as exc:
        return [f"'{where}': {exc}"]
    return []


def constructor_arguments(cls: Callable[..., Any], exclude: tuple[str, ...] = ()) -> list[str]:
    """The keyword arguments a class accepts (from its signature), less ``exclude``."""
    params = inspect.signature(cls).parameters.values()
    return [
        p.name
        for p in params
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and p.name not in exclude
    ]


def _build(what: str, cls: Callable[..., Any], args: dict[str, Any], where: str) -> list[str]:
    """Construct ``cls(**args)`` to let it check the values; its complaint, keyed."""
    try:
        cls(**args)
    except (TypeError, ValueError) as exc:
        return [f"'{where}': bad value for {what}: {exc}"]
    return []


def _matches_hint(value: Any, hint: Any) -> bool:
    """Whether a TOML value fits a constructor's annotation (float, int, str, tuple)."""
    origin = typing.get_origin(hint) or hint
    if origin is tuple:
        return isinstance(value, list) and all(_is_kind(v, float) for v in value)
    if origin in (int, float, str, bool):
        return _is_kind(value, origin)
    return True  # anything else is left to the constructor


def _hint_name(hint: Any) -> str:
    origin = typing.get_origin(hint) or hint
    return "a list of numbers" if origin is tuple else _kind_name(origin)


def _check_effects(value: list, where: str) -> list[str]:
    out = []
    for i, entry in enumerate(value):
        at = f"{where}[{i}]"
        if not isinstance(entry, dict):
            out.append(f"'{at}' must be a table like {{ kind = \"backlash\", play_m = 2e-5 }}")
            continue
        kind = entry.get("kind")
        if not isinstance(kind, str):
            out.append(f"'{at}.kind' is missing (which effect: {', '.join(EFFECTS)})")
            continue
        if kind not in EFFECTS:
            out.append(f"'{at}.kind': " + unknown_name_message("effect", kind, list(EFFECTS)))
            continue
        accepted = constructor_arguments(EFFECTS[kind], EFFECT_EXCLUDED_ARGS)
        args = {k: v for k, v in entry.items() if k != "kind"}
        bad = [a for a in args if a not in accepted]
        for a in bad:
            best = _closest(a, accepted)
            hint = f"did you mean '{best}'?" if best else f"accepted: {', '.join(accepted)}"
            out.append(f"'{at}.{a}': effect '{kind}' has no argument '{a}'; {hint}")
        if bad:
            continue
        hints = typing.get_type_hints(EFFECTS[kind])
        wrong = [a for a, v in args.items() if not _matches_hint(v, hints.get(a))]
        for a in wrong:
            out.append(f"'{at}.{a}': effect '{kind}' takes {_hint_name(hints[a])}, got {args[a]!r}")
        if not wrong:
            out += _build(f"effect '{kind}'", EFFECTS[kind], args, at)
    return out


def _check_estimators(value: list, where: str) -> list[str]:
    from calib.estimators import ESTIMATORS

    out = []
    labels: list[str] = []
    for i, entry in enumerate(value):
        at = f"{where}[{i}]"
        if isinstance(entry, str):
            if entry not in ESTIMATORS:
                out.append(f"'{at}': " + unknown_name_message("estimator", entry, list(ESTIMATORS)))
            labels.append(entry)
            continue
        if not isinstance(entry, dict):
            out.append(f"'{at}' must be a name or a table {{ label, method, options... }}")
            continue
        label, method = entry.get("label"), entry.get("method")
        if not isinstance(label, str) or not isinstance(method, str):
            out.append(f"'{at}' needs 'label' and 'method' (strings)")
            continue
        labels.append(label)
        if method not in ESTIMATORS:
            out.append(
                f"'{at}.method': " + unknown_name_message("estimator", method, list(ESTIMATORS))
            )
            continue
        accepted = constructor_arguments(ESTIMATORS[method])
        opts = {k: v for k, v in entry.items() if k not in ("label", "method")}
        bad = [a for a in opts if a not in accepted]
        for a in bad:
            best = _closest(a, accepted)
            hint = f"did you mean '{best}'?" if best else f"accepted: {', '.join(accepted)}"
            out.append(f"'{at}.{a}': estimator '{method}' has no option '{a}'; {hint}")
        if not bad:
            out += _build(f"estimator '{method}'", ESTIMATORS[method], opts, at)
    dupes = sorted({x for x in labels if labels.count(x) > 1})
    if dupes:
        out.append(f"'{where}': labels must be unique, repeated: {dupes}")
    return out


def _check_truth(data: dict[str, Any], where: str) -> list[str]:
    has_file, has_random = "values_file" in data, "random" in data
    if has_file and has_random:
        return [f"give either '{where}.values_file' or [{where}.random], not both"]
    if not has_file and not has_random:
        return [f"[{where}] needs 'values_file' (explicit errors) or a [{where}.random] table"]
    return []


# ----------------------------------------------------------------- the studies' schemas

# An upper bound on every count (poses, nodes, draws, repeats): 36 times the largest real
# dataset seen (2773 poses) and ten times the paper's 10^4 Monte Carlo runs; a larger count
# is a typo that would run for days or exhaust memory rather than an experiment
