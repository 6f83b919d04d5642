"""What a sweep varies: ``--set key=value[,value ...]`` overrides, seeds, and the plan of runs.

An override replaces one dotted key of a loaded scenario's data (``tracker.sigma_mm=0.005``);
a value is read as a TOML value (``0.005``, ``[0, 0, 1]``, ``"text"``), or as a plain string
when it is not one (``kind=gaussian``). ``key=a,b,c`` sweeps the key over those values. The
overridden scenario is checked against its study's schema (:func:`scenarios.config.validate`),
so an unknown key or a value out of range is refused before anything runs.

Seeds: run ``i`` of a sweep draws from child ``i`` of ``numpy.random.SeedSequence(seed)`` (the
scenario's own seed), two 32-bit words: one for the truth, one for the measurement noise.
Every study takes one ``seed`` today, used first for the truth draw ([truth.random]) and then
for the noise; the sweep separates them by overriding keys only:

* ``--over both``: ``seed`` = the run's truth word; truth and noise both change (run ``i`` is
  exactly ``python -m scenarios run`` with that seed).
* ``--over noise``: the truth is held: a ``truth.values_file`` scenario keeps its file; a
  [truth.random] one has its truth drawn once from the scenario's own seed and written to a
  values file in each run's folder; ``seed`` = the run's noise word.
* ``--over truth``: the truth is drawn from [truth.random] with the run's truth word and
  written to a values file; ``seed`` stays the scenario's, so the noise stream is held.
"""

from __future__ import annotations

import copy
import itertools
import re
import tomllib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from scenarios.config import SCHEMAS, Scenario, ScenarioError, validate

OVER = ("truth", "noise", "both")
DELETE = None  # an override to None removes the key (e.g. truth.random when a file replaces it)
PROTECTED = ("study", "name")  # they choose the runner and the results folder


# ------------------------------------------------------------------------- --set values


def _split_top_level(text: str) -> list[str]:
    """``a,[1,2],"x,y"`` -> ``['a', '[1,2]', '"x,y"']``: commas outside brackets and quotes."""
    parts, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts]


def parse_value(text: str) -> Any:
    """A TOML value (``0.005``, ``true``, ``[1, 2]``, ``"s"``), else the text as a string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


_KEY = re.compile(r"[A-Za-z0-9_-]+(\.[A-Za-z0-9_-]+)*")


def parse_set(item: str) -> tuple[str, list[Any]]:
    """``key=v1,v2`` -> ``('key', [v1, v2])``; a clear ScenarioError on a malformed item."""
    key, sep, values = item.partition("=")
    key = key.strip()
    if not sep or not _KEY.fullmatch(key):
        raise ScenarioError(f"--set {item!r}: expected key=value[,value ...] with a dotted key")
    if key in PROTECTED:
        raise ScenarioError(f"--set {item!r}: '{key}' cannot be overridden in a sweep")
    parts = _split_top_level(values)
    if any(p == "" for p in parts):
        raise ScenarioError(f"--set {item!r}: empty value")
    return key, [parse_value(p) for p in parts]


def parse_sets(items: list[str]) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = {}
    for item in items:
        key, values = parse_set(item)
        if key in out:
            raise ScenarioError(f"--set: '{key}' given twice")
        out[key] = values
    return out


# ------------------------------------------------------------------------ overriding keys


def overridden_data(data: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """A deep copy of ``data`` with each dotted key set (tables made as needed) or, for
    ``None``, removed."""
    out = copy.deepcopy(data)
    for dotted, value in overrides.items():
        node = out
        *parents, last = dotted.split(".")
        for part in parents:
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise ScenarioError(f"--set '{dotted}': '{part}' is a value, not a table")
            node = child
        if value is DELETE:
            node.pop(last, None)
        else:
            node[last] = copy.deepcopy(value)
    return out


def overridden(scenario: Scenario, overrides: dict[str, Any]) -> Scenario:
    """``scenario`` with ``overrides`` applied and checked against its study's schema."""
    if not overrides:
        return scenario
    data = overridden_data(scenario.data, overrides)
    out = Scenario(scenario.name, scenario.study, scenario.path, data, SCHEMAS[scenario.study])
    try:
        validate(out, SCHEMAS[scenario.study])
    except ScenarioError as exc:
        shown = ", ".join(f"{k}={v!r}" for k, v in overrides.items())
        raise ScenarioError(f"with overrides {shown}: {exc}") from exc
    return out


# ------------------------------------------------------------------------------- seeds


def run_seeds(base_seed: int, n: int) -> list[tuple[int, int]]:
    """(truth seed, noise seed) of runs 0..n-1; run ``i``'s do not depend on ``n``."""
    children = np.random.SeedSequence(base_seed).spawn(n)
    return [tuple(int(w) for w in c.generate_state(2)) for c in children]


def _schema_has(study: str, dotted: str) -> bool:
    return SCHEMAS[study].lookup(dotted) is not None


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep, as plain data a task can be given."""

    run_id: str
    index: int  # seed index
    settings: dict[str, Any]  # the swept settings' values for this run
    overrides: dict[str, Any]  # every key set on the scenario (settings and seeds)
    truth_seed: int | None = None  # draw the truth from [truth.random] with it (in the task)
    seeds: dict[str, int] = field(default_factory=dict)  # for the record

    def plain(self) -> dict[str, Any]:
        return {
            "run_id": self.run_id,
            "index": self.index,
            "settings": self.settings,
            "overrides": self.overrides,
            "truth_seed": self.truth_seed,
            "seeds": self.seeds,
        }


def _label(value: Any) -> str:
    text = value if isinstance(value, str) else repr(value)
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "_"


def run_id(index: int, settings: dict[str, Any]) -> str:
    parts = [f"{k.rsplit('.', 1)[-1]}-{_label(v)}" for k, v in settings.items()]
    return "_".join(["run", *parts, f"s{index:04d}"])


def _seed_overrides(
    scenario: Scenario, over: str, index: int, truth_word: int, noise_word: int, n_seeds: int
) -> tuple[dict[str, Any], int | None, dict[str, int]]:
    study = scenario.study
    if not _schema_has(study, "seed"):
        if n_seeds > 1:
            raise ScenarioError(
                f"{scenario.path}: study '{study}' takes no seed; sweep only --set values "
                "with --seeds 1"
            )
        return {}, None, {}
    base = scenario.get("seed", int)
    has_file = "values_file" in scenario.data.get("truth", {})
    file_ok = _schema_has(study, "truth.values_file") and _schema_has(study, "truth.random")
    if over == "both":
        return {"seed": truth_word}, None, {"seed": truth_word}
    if over == "noise":
        if has_file:
            return {"seed": noise_word}, None, {"seed": noise_word}
        if not file_ok:
            raise ScenarioError(
                f"{scenario.path}: study '{study}' draws truth and noise from one seed and "
                "cannot hold its truth in a values file; use --over both"
            )
        return {"seed": noise_word}, base, {"truth_seed": base, "noise_seed": noise_word}
    # over == "truth"
    if has_file:
        raise ScenarioError(
            f"{scenario.path}: the truth is fixed by 'truth.values_file'; --over truth needs "
            "a [truth.random] draw (use --over noise)"
        )
    if not file_ok:
        raise ScenarioError(
            f"{scenario.path}: study '{study}' draws truth and noise from one seed and "
            "cannot hold its noise apart; use --over both"
        )
    return {}, truth_word, {"truth_seed": truth_word, "noise_seed": base}


def plan_runs(
    scenario: Scenario, n_seeds: int, over: str, sets: dict[str, list[Any]]
) -> list[RunSpec]:
    """Every run: each combination of the ``sets`` values, times ``n_seeds`` seeds. Each
    run's overridden scenario is validated here, before anything runs."""
    if over not in OVER:
        raise ScenarioError(f"--over must be one of {list(OVER)}, got {over!r}")
    if n_seeds < 1:
        raise ScenarioError(f"--seeds must be >= 1, got {n_seeds}")
    base_seed = scenario.get("seed", int) if _schema_has(scenario.study, "seed") else 0
    seeds = run_seeds(base_seed, n_seeds)
    swept = {k: v for k, v in sets.items() if len(v) > 1}
    fixed = {k: v[0] for k, v in sets.items() if len(v) == 1}
    runs = []
    for combo in itertools.product(*swept.values()):
        settings = dict(zip(swept, combo, strict=True))
        for i, (truth_word, noise_word) in enumerate(seeds):
            seed_keys, truth_seed, record = _seed_overrides(
                scenario, over, i, truth_word, noise_word, n_seeds
            )
            overrides = {**fixed, **settings, **seed_keys}
            # with a truth seed, the task also replaces [truth.random] by the values file it
            # draws; the rest is checked now, the whole again in the task
            overridden(scenario, overrides)
            runs.append(RunSpec(run_id(i, settings), i, settings, overrides, truth_seed, record))
    return runs
