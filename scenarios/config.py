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

import difflib
import inspect
import re
import tomllib
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twin.formats.parameter_file import read_utf8

REPO_ROOT = Path(__file__).resolve().parent.parent
SCENARIO_DIR = Path(__file__).resolve().parent


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
    from scenarios.machine_setup import EFFECT_EXCLUDED_ARGS, EFFECTS

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
    from calib.estimators.registry import ESTIMATORS

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
MAX_COUNT = 100_000
_COUNT = Key(int, required=True, min=1, max=MAX_COUNT)
_NONNEG = Key(float, min=0)
_POSITION_MM = Key(list, item=float, length=3)
_HALF_WIDTH_MM = Key(list, required=True, item=float, length=2, above=0)

_TRUTH_RANDOM = Table(
    {
        "distribution": Key(str, choices=("uniform", "gaussian")),
        "translation_mm": Key(float, required=True, min=0),
        "rotation_deg": _NONNEG,
        "encoder_mm": _NONNEG,
        "encoder_deg": _NONNEG,
    }
)


def _truth(**extra: Key | Table) -> Table:
    return Table(
        {"values_file": Key(str, path=True), "random": _TRUTH_RANDOM, **extra},
        required=True,
        check=_check_truth,
    )


def _base(**keys: Key | Table) -> Table:
    """The keys every study reads, and a study's own."""
    return Table(
        {
            "name": Key(str, check=_check_name),
            "study": Key(str, required=True),
            "description": Key(str),
            "model": Key(str, required=True, path=True),
            "error_model": Key(str, required=True, path=True),
            **keys,
        }
    )


_SEED = Key(int, required=True, min=0)
_POSE_NOISE = Table(
    {
        "kind": Key(str, required=True, choices=("uniform", "gaussian")),
        "position_mm": Key(float, required=True, min=0),
        "rotation_deg": Key(float, required=True, min=0),
    },
    required=True,
)

_ARM_TRACKER = Table(
    {
        "position_mm": Key(list, required=True, item=float, length=3),
        "rotation_deg": Key(list, required=True, item=float, length=3),
        "noise": Key(str, required=True, check=_check_noise_spec),
        "sigma_mm": Key(float, required=True, above=0),
    },
    required=True,
)
_ARM_PLAN = Table(
    {
        "calibration_poses": _COUNT,
        "test_poses": _COUNT,
        "joint_fraction": Key(float, required=True, above=0, max=1),
    },
    required=True,
)

PLACEMENTS = ("interpolated", "extrapolated", "tilted")


def _check_placements(value: list, where: str) -> list[str]:
    out = [
        f"'{where}[{i}]': " + unknown_name_message("placement", p, list(PLACEMENTS))
        for i, p in enumerate(value)
        if p not in PLACEMENTS
    ]
    if len(set(value)) != len(value):
        out.append(f"'{where}' names a placement twice")
    return out


def _liu_vs_ols_keys() -> dict[str, Key | Table]:
    """The keys of liu_vs_ols's plan and twin (its single run, draw study and regime map)."""
    return dict(
        seed=_SEED,
        truth=_truth(effects=Key(list, check=_check_effects)),
        tracker=Table(
            {
                "sigma_mm": Key(float, required=True, min=0),
                "position_mm": Key(list, required=True, item=float, length=3),
                "repeats": Key(int, min=1, max=MAX_COUNT),
            },
            required=True,
        ),
        workspace=Table({"half_width_mm": _HALF_WIDTH_MM}, required=True),
        layers=Table(
            {
                "upper": Key(float, required=True),
                "middle": Key(float, required=True),
                "lower": Key(float, required=True),
            },
            required=True,
        ),
        coarse=Table({"nodes_per_side": _COUNT, "rel_tol": Key(float, above=0)}, required=True),
        fine=Table(
            {
                "nodes_per_side": _COUNT,
                "estimators": Key(list, required=True, min_items=1, check=_check_estimators),
            },
            required=True,
        ),
        scoring=Table({"nodes_per_side": Key(int, min=1, max=MAX_COUNT)}),
    )


SCHEMAS: dict[str, Table] = {
    "hexapod_paper": _base(
        seed=_SEED,
        truth=_truth(),
        tracker=Table(
            {
                "position_mm": Key(list, required=True, item=float, length=3),
                "noise": Key(str, required=True, check=_check_noise_spec),
                "repeats": Key(int, min=1, max=MAX_COUNT),
            },
            required=True,
        ),
        pose_noise=_POSE_NOISE,
        plans=Table(
            {"noise_free_poses": _COUNT, "few_poses": _COUNT, "many_poses": _COUNT},
            required=True,
        ),
        verification=Table(
            {
                "nodes_per_axis": _COUNT,
                "orientations_per_node": _COUNT,
                "margin": Key(float, min=0, below=0.5),
                "stroke_margin_mm": _NONNEG,
            },
            required=True,
        ),
    ),
    "liu_vs_ols": _base(
        **_liu_vs_ols_keys(),
        # the single scenario needs it; the draw study (with [draws]) does without
        monte_carlo=Table({"runs": Key(int, required=True, min=2, max=MAX_COUNT)}),
        # the draw study: the whole scenario over n truth draws (seeds seed, seed + 1, ...)
        draws=Table(
            {
                "n": Key(int, required=True, min=1, max=MAX_COUNT),
                "estimators": Key(list, min_items=1, check=_check_estimators),
                "engine": Key(str, choices=("ray", "local")),
            }
        ),
        # the loop after the fine calibration (diagnosis, effect, refit, compensation)
        loop=Table({"estimator": Key(str)}),
    ),
    # liu_vs_ols's plan and twin over a grid of tracker noise and test placements
    "liu_regime": _base(
        **_liu_vs_ols_keys(),
        regime=Table(
            {
                "sigmas_mm": Key(list, required=True, item=float, min_items=1, above=0),
                "placements": Key(
                    list, required=True, item=str, min_items=1, check=_check_placements
                ),
                "draws": Key(int, required=True, min=1, max=MAX_COUNT),
                "extrapolated_offset_mm": Key(float, above=0),
                "extrapolated_side": Key(str, choices=("below", "above")),
                "stroke_margin_mm": _NONNEG,
                "tilt_deg": Key(list, item=float, length=2, min=0, below=90),
                "tilt_seed": Key(int, min=0),
                "engine": Key(str, choices=("ray", "local")),
            },
            required=True,
        ),
    ),
    "optimal_poses": _base(
        seed=_SEED,
        truth=_truth(),
        pose_noise=_POSE_NOISE,
        design=Table(
            {
                "index": Key(
                    str,
                    choices=(
                        "product",
                        "condition",
                        "min_singular",
                        "noise_amplification",
                        "d_optimality",
                    ),
                ),
                "random_starts": _COUNT,
                "initial_poses": _COUNT,
                "max_poses": _COUNT,
                "extra_random_candidates": Key(int, required=True, min=0),
            },
            required=True,
            check=lambda d, w: (
                [f"'{w}.max_poses' must be >= '{w}.initial_poses' ({d['initial_poses']})"]
                if d["max_poses"] < d["initial_poses"]
                else []
            ),
        ),
        evaluation=Table({"noise_draws": _COUNT, "random_many": _COUNT}, required=True),
    ),
    "polisher_identifiability": _base(
        plan=Table(
            {
                "layer_heights_mm": Key(list, required=True, item=float, min_items=1),
                "nodes_per_side": _COUNT,
                "half_width_mm": _HALF_WIDTH_MM,
            },
            required=True,
        ),
        checks=Table({"fd_poses": Key(int, min=1, max=MAX_COUNT)}),
        plan_comparison=Table(
            {
                "plans": Key(
                    list,
                    item=Table(
                        {
                            "layer_heights_mm": Key(list, required=True, item=float, min_items=1),
                            "nodes_per_side": _COUNT,
                        }
                    ),
                )
            }
        ),
    ),
    "serial_arm": _base(
        seed=_SEED,
        truth=Table({"random": Table(_TRUTH_RANDOM.keys, required=True)}, required=True),
        tracker=_ARM_TRACKER,
        plan=_ARM_PLAN,
        compensation=Table(
            {
                "desired_poses": _COUNT,
                "joint_fraction": Key(float, required=True, above=0, max=1),
                "stroke_margin_deg": Key(float, required=True, min=0),
            },
            required=True,
        ),
        variants=Table(
            {
                "three_reflectors": Table(
                    {
                        "model": Key(str, required=True, path=True),
                        "error_model": Key(str, required=True, path=True),
                    },
                    required=True,
                )
            },
            required=True,
        ),
    ),
    "measured_loop": _base(
        seed=_SEED,
        truth=Table(
            {
                "random": Table(_TRUTH_RANDOM.keys, required=True),
                "effects": Key(list, check=_check_effects),
            },
            required=True,
        ),
        tracker=_ARM_TRACKER,
        plan=_ARM_PLAN,
    ),
    "undeclared_effect": _base(
        seed=_SEED,
        truth=_truth(
            effects=Key(list, check=_check_effects),
            tracker_scale_error=Key(float, above=-1),
        ),
        tracker=Table(
            {"sigma_mm": Key(float, required=True, min=0), "position_mm": _POSITION_MM},
            required=True,
        ),
        plan=Table({"calibration_poses": _COUNT, "test_poses": _COUNT}, required=True),
    ),
    "diagnosis_benchmark": _base(
        machine=Key(str),
        truth=Table({"random": Table(_TRUTH_RANDOM.keys, required=True)}, required=True),
        tracker=Table(
            {"sigma_mm": Key(float, required=True, above=0), "position_mm": _POSITION_MM},
            required=True,
        ),
        plan=Table(
            {"calibration_poses": _COUNT, "test_poses": _COUNT, "audit_poses": _COUNT},
            required=True,
        ),
        benchmark=Table(
            {
                # twin effect kinds (scenarios.machine_setup.EFFECTS), each at its defaults
                "kinds": Key(
                    list,
                    required=True,
                    item=str,
                    check=lambda v, w: _check_effects([{"kind": k} for k in v], w),
                ),
                "multipliers": Key(list, required=True, item=float, min_items=1, above=0),
                "seeds": Key(list, required=True, item=int, min_items=1, min=0),
                "none_seeds": Key(list, required=True, item=int, min=0),
            },
            required=True,
        ),
        extra_machines=Key(
            list,
            item=Table(
                {
                    "label": Key(str, required=True),
                    "model": Key(str, required=True),
                    "error_model": Key(str, required=True),
                    "kinds": Key(
                        list,
                        item=str,
                        check=lambda v, w: _check_effects([{"kind": k} for k in v], w),
                    ),
                }
            ),
        ),
    ),
}


# ------------------------------------------------------------------------- the scenario


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
