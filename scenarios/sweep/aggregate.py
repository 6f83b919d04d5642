"""The distribution of every number over a sweep's runs: median, p05, p95, mean, std.

A run's summary is flattened to dotted keys (``optimal.param_max_abs_mm``); every key whose
value is a number (not a bool, not a list) in at least one run gets statistics over the runs
that have a number there. ``std`` is the sample standard deviation (ddof 1; 0 for one run);
percentiles interpolate linearly (numpy's default).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

STATS = ("median", "p05", "p95", "mean", "std")


def flatten_numbers(summary: dict[str, Any], prefix: str = "") -> dict[str, float]:
    """Every numeric leaf of a nested summary by dotted key (lists and bools left out)."""
    out: dict[str, float] = {}
    for k, v in summary.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten_numbers(v, f"{key}."))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            if math.isfinite(float(v)):
                out[key] = float(v)
    return out


def statistics(values: Iterable[float]) -> dict[str, float | int]:
    v = np.asarray(list(values), dtype=float)
    return {
        "n": int(v.size),
        "median": float(np.median(v)),
        "p05": float(np.percentile(v, 5)),
        "p95": float(np.percentile(v, 95)),
        "mean": float(np.mean(v)),
        "std": float(np.std(v, ddof=1)) if v.size > 1 else 0.0,
    }


def numeric_table(summaries: list[dict[str, Any]]) -> dict[str, list[float]]:
    """Dotted key -> its values over the runs (in run order; runs without it skipped)."""
    table: dict[str, list[float]] = {}
    for s in summaries:
        for k, v in flatten_numbers(s).items():
            table.setdefault(k, []).append(v)
    return table


def metric_statistics(summaries: list[dict[str, Any]]) -> dict[str, dict[str, float | int]]:
    return {k: statistics(v) for k, v in numeric_table(summaries).items()}


def settings_label(settings: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in settings.items()) or "all runs"


def aggregate(
    name: str,
    engine: str,
    swept: dict[str, Any],
    results: list[dict[str, Any]],
) -> dict[str, Any]:
    """The sweep's summary.json from the runs' results (``run_task``'s dicts, in run order,
    each with ``spec``). With swept settings, statistics per combination as well."""
    ok = [r for r in results if r["status"] == "ok"]
    summary: dict[str, Any] = {
        "scenario": name,
        "engine": engine,
        "n_runs": len(results),
        "n_failed": len(results) - len(ok),
        "swept": swept,
        "metrics": metric_statistics([r["summary"] for r in ok]),
    }
    if swept.get("settings"):
        groups: dict[str, list[dict[str, Any]]] = {}
        for r in ok:
            groups.setdefault(settings_label(r["spec"]["settings"]), []).append(r["summary"])
        summary["by_setting"] = {
            label: {"n_runs": len(s), "metrics": metric_statistics(s)}
            for label, s in groups.items()
        }
    summary["runs"] = [
        {
            "run_id": r["run_id"],
            "status": r["status"],
            "settings": r["spec"]["settings"],
            "seeds": r["spec"]["seeds"],
            **({"error": r["error"]} if r["status"] != "ok" else {}),
            **({"resumed": True} if r.get("resumed") else {}),
        }
        for r in results
    ]
    return summary
