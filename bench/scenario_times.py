"""Wall time of every scenario (scenarios/studies/*/*.toml) run whole through scenarios.runner
into a temporary results root, never results/. The slow studies (optimal_poses, every
diagnosis_benchmark*, the 100-draw liu_vs_ols_draws, the liu_regime map; minutes to tens of
minutes each) only with BENCH_ALL=1.

liu_vs_ols is also timed without figures and recording (``run_scenario(..., record=False,
figures=False)``, the runner's switch; the study computes the same numbers).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from scenarios.config import find_scenario, scenario_files
from scenarios.runner import run_scenario

SLOW = ("optimal_poses", "diagnosis_benchmark", "liu_vs_ols_draws", "liu_regime")  # name prefixes


def is_slow(name: str) -> bool:
    return name.startswith(SLOW)


def scenario_names(everything: bool) -> list[str]:
    names = sorted(p.stem for p in scenario_files())
    return [n for n in names if everything or not is_slow(n)]


def _timed(name: str, root: Path, **kwargs) -> float:
    t0 = time.perf_counter()
    run_scenario(str(find_scenario(name)), root, quiet=True, **kwargs)
    return time.perf_counter() - t0


def scenario_times(everything: bool | None = None) -> tuple[dict, list[str], dict]:
    """{scenario_<name>_s: seconds}, the scenarios left out, and {name: error} of those that
    failed (a failing scenario does not stop the benchmark; its time is left out)."""
    if everything is None:
        everything = os.environ.get("BENCH_ALL", "") in ("1", "yes", "true")
    out: dict = {}
    errors: dict = {}
    names = scenario_names(everything)
    skipped = [n for n in scenario_names(True) if n not in names]
    with tempfile.TemporaryDirectory(prefix="bench-results-") as tmp:
        root = Path(tmp)
        for name in names:
            try:
                out[f"scenario_{name}_s"] = _timed(name, root)
            except Exception as exc:  # someone else's scenario broken: say so, go on
                errors[name] = f"{type(exc).__name__}: {exc}"
                print(f"scenario {name} FAILED: {errors[name]}", flush=True)
                continue
            print(f"scenario {name} {out[f'scenario_{name}_s']:.1f} s", flush=True)
            if name == "liu_vs_ols":
                t = _timed(name, root / "no_figures", record=False, figures=False)
                out["scenario_liu_vs_ols_no_figures_s"] = t
                print(f"scenario liu_vs_ols without figures or recording {t:.1f} s", flush=True)
    return out, skipped, errors
