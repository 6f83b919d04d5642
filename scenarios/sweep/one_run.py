"""One run of a sweep: a study on an overridden scenario, into ``<out_root>/<run_id>/``.

:func:`run_task` is the Ray task (and the local engine's): plain data in (the scenario's
path, its overrides, the run's id, the output root), plain data out (the run's summary, or
its error). The run's folder is written whole or not at all (``runner.replaced_whole``):
``summary.json``, ``report.md``, the study's figures, and ``run.json`` (what was run). A run
that fails leaves ``error.json`` instead (its error and traceback) and does not raise.
"""

from __future__ import annotations

import importlib
import json
import time
import traceback
from pathlib import Path
from typing import Any

from common.atomic_files import plain_json, write_json_atomic, write_text_atomic
from scenarios.config import Scenario, load_scenario
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.runner import STUDIES, replaced_whole
from scenarios.sweep.settings import DELETE, overridden

RUN_FILE = "run.json"
ERROR_FILE = "error.json"
SUMMARY_FILE = "summary.json"
TRUTH_FILE = "truth_values.toml"


def _write_truth(scenario: Scenario, truth_seed: int, path: Path) -> None:
    """The truth drawn from the scenario's [truth.random] as the study would draw it first
    from ``default_rng(truth_seed)``, as a ``[values]`` file (mm, deg)."""
    import numpy as np

    from scenarios.machine_setup import load_nominal
    from scenarios.truth_draw import TruthSpec, draw_truth

    _, params = load_nominal(scenario)
    values = draw_truth(
        params, TruthSpec.from_scenario(scenario), np.random.default_rng(truth_seed)
    )
    shown = params.to_display(values)
    lines = [
        f"# drawn by the sweep from [truth.random] of {scenario.path} with seed {truth_seed}",
        'unit = "mm"',
        "",
        "[values]",
        *(f'"{n}" = {float(v)!r}' for n, v in zip(params.names, shown, strict=True)),
    ]
    write_text_atomic(path, "\n".join(lines) + "\n")


def run_study(
    scenario_path: str,
    overrides: dict[str, Any],
    out_dir: Path,
    truth_seed: int | None = None,
    record: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Run the study of the overridden scenario into ``out_dir`` (replaced whole)."""
    base = load_scenario(scenario_path)
    run, report = (importlib.import_module(m) for m in STUDIES[base.study])
    with replaced_whole(out_dir) as work:
        if truth_seed is not None:
            _write_truth(base, truth_seed, work / TRUTH_FILE)
            overrides = {
                **overrides,
                "truth.random": DELETE,
                "truth.values_file": str((work / TRUTH_FILE).resolve()),  # read during the run
            }
        scenario = overridden(base, overrides)
        with Recorder(None, f"pkm-calib-{scenario.name}") as recorder:
            summary = run.run(scenario, work, Progress(scenario.name, quiet=True), recorder)
        write_json_atomic(work / SUMMARY_FILE, summary)
        write_text_atomic(work / "report.md", report.report(summary))
        write_json_atomic(work / RUN_FILE, record or {})
    return summary


def run_task(
    scenario_path: str,
    overrides: dict[str, Any],
    run_id: str,
    out_root: str,
    truth_seed: int | None = None,
    spec: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """One run as a task: ``{"run_id", "status": "ok", "summary"}`` or ``{..., "status":
    "failed", "error", "traceback"}``; never raises for a study's error."""
    from threadpoolctl import threadpool_limits

    out_dir = Path(out_root) / run_id
    t0 = time.perf_counter()
    try:
        with threadpool_limits(1):  # one BLAS thread: the same numbers on every engine
            summary = run_study(scenario_path, overrides, out_dir, truth_seed, spec)
    except Exception as exc:
        failed = {
            "run_id": run_id,
            "status": "failed",
            "error": f"{type(exc).__name__}: {exc}",
            "traceback": traceback.format_exc(),
            "spec": spec or {},
            "runtime_s": time.perf_counter() - t0,
        }
        try:  # the folder holds the error alone, not an older run's results
            with replaced_whole(out_dir) as work:
                write_json_atomic(work / ERROR_FILE, failed)
        except OSError:
            pass  # the driver records it as well
        return failed
    return {
        "run_id": run_id,
        "status": "ok",
        "summary": plain_json(summary),
        "runtime_s": time.perf_counter() - t0,
    }


def finished(out_dir: Path, spec: dict[str, Any]) -> dict[str, Any] | None:
    """The summary of a run already done with the same spec (for resuming), else None."""
    try:
        done = json.loads((out_dir / RUN_FILE).read_text())
        summary = json.loads((out_dir / SUMMARY_FILE).read_text())
    except (OSError, ValueError):
        return None
    return summary if done == json.loads(json.dumps(spec)) else None
