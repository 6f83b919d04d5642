"""Runs a scenario by name or path and writes results/<name>/ (summary.json, report.md)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from scenarios.config import REPO_ROOT, Scenario, ScenarioError, load_scenario
from scenarios.progress import Progress
from scenarios.results import write_json_atomic, write_text_atomic

StudyFn = Callable[[Scenario, Path, Progress], dict[str, Any]]
ReportFn = Callable[[dict[str, Any]], str]


def _studies() -> dict[str, tuple[StudyFn, ReportFn]]:
    from scenarios import (
        hexapod_paper,
        hexapod_report,
        polisher_identifiability,
        polisher_identifiability_report,
    )

    return {
        "hexapod_paper": (hexapod_paper.run, hexapod_report.report),
        "polisher_identifiability": (
            polisher_identifiability.run,
            polisher_identifiability_report.report,
        ),
    }


def run_scenario(
    name_or_path: str, results_root: Path | None = None, quiet: bool = False
) -> tuple[dict[str, Any], Path]:
    """Run one scenario; returns its summary and its output folder."""
    scenario = load_scenario(name_or_path)
    studies = _studies()
    if scenario.study not in studies:
        raise ScenarioError(
            f"{scenario.path}: unknown study '{scenario.study}'; known: {sorted(studies)}"
        )
    run, report = studies[scenario.study]
    out_dir = (results_root or REPO_ROOT / "results") / scenario.name
    out_dir.mkdir(parents=True, exist_ok=True)
    progress = Progress(scenario.name, quiet=quiet)
    summary = run(scenario, out_dir, progress)
    write_json_atomic(out_dir / "summary.json", summary)
    write_text_atomic(out_dir / "report.md", report(summary))
    progress.step(f"wrote {out_dir / 'summary.json'} and report.md")
    return summary, out_dir
