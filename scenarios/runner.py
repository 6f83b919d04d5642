"""Runs a scenario by name or path and writes results/<name>/ (summary.json, report.md)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from scenarios.config import REPO_ROOT, Scenario, ScenarioError, load_scenario
from scenarios.progress import Progress
from scenarios.recording import Recorder
from scenarios.results import write_json_atomic, write_text_atomic

StudyFn = Callable[[Scenario, Path, Progress, Recorder], dict[str, Any]]
ReportFn = Callable[[dict[str, Any]], str]


# study name -> (module with run(scenario, out_dir, progress), module with report(summary))
STUDIES = {
    "hexapod_paper": ("scenarios.hexapod_paper", "scenarios.hexapod_report"),
    "polisher_identifiability": (
        "scenarios.polisher_identifiability",
        "scenarios.polisher_identifiability_report",
    ),
    "liu_vs_ols": ("scenarios.liu_vs_ols", "scenarios.liu_vs_ols_report"),
    "optimal_poses": ("scenarios.optimal_poses", "scenarios.optimal_poses_report"),
    "undeclared_effect": ("scenarios.undeclared_effect", "scenarios.undeclared_effect_report"),
}


def _study(name: str) -> tuple[StudyFn, ReportFn]:
    run_module, report_module = STUDIES[name]
    return (
        importlib.import_module(run_module).run,
        importlib.import_module(report_module).report,
    )


def run_scenario(
    name_or_path: str,
    results_root: Path | None = None,
    quiet: bool = False,
    view: bool = False,
    record: bool = True,
) -> tuple[dict[str, Any], Path]:
    """Run one scenario; returns its summary and its output folder.

    The rerun recording goes to ``<out>/<name>.rrd`` (``record``); ``view`` also opens the
    viewer."""
    scenario = load_scenario(name_or_path)
    if scenario.study not in STUDIES:
        raise ScenarioError(
            f"{scenario.path}: unknown study '{scenario.study}'; known: {sorted(STUDIES)}"
        )
    run, report = _study(scenario.study)
    out_dir = (results_root or REPO_ROOT / "results") / scenario.name
    out_dir.mkdir(parents=True, exist_ok=True)
    progress = Progress(scenario.name, quiet=quiet)
    rrd = out_dir / f"{scenario.name}.rrd" if record else None
    with Recorder(rrd, f"pkm-calib-{scenario.name}", spawn_viewer=view) as recorder:
        recorder.send_blueprint()
        summary = run(scenario, out_dir, progress, recorder)
    if rrd is not None:
        summary["recording"] = rrd.name
    write_json_atomic(out_dir / "summary.json", summary)
    write_text_atomic(out_dir / "report.md", report(summary))
    progress.step(f"wrote {out_dir / 'summary.json'} and report.md")
    return summary, out_dir
