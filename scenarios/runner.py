"""Runs a scenario by name or path and writes results/<name>/ (summary.json, report.md).

A results folder is replaced whole or not at all: the run writes into a temporary sibling
``results/.<name>.partial-XXXX`` and only at the end swaps it in for ``results/<name>``. On any
failure, Ctrl-C included, the temporary folder is removed and the previous results stay; what
a killed run left behind is recovered by the next run (:mod:`scenarios.results_folder`).
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.atomic_files import write_json_atomic, write_text_atomic
from scenarios.config import REPO_ROOT, Scenario, ScenarioError, load_scenario
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.results_folder import (
    KEPT,
    ResultsWriteError,
    final_paths_in,
    name_final_paths,
    replaced_whole,
)
from scenarios.studies import STUDIES

__all__ = [
    "KEPT",
    "STUDIES",
    "ResultsWriteError",
    "RunInterrupted",
    "replaced_whole",
    "run_scenario",
]

StudyFn = Callable[[Scenario, Path, Progress, Recorder], dict[str, Any]]
ReportFn = Callable[[dict[str, Any]], str]


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C during a run; ``out_dir`` (the results folder) was left as it was."""

    def __init__(self, out_dir: Path) -> None:
        super().__init__(f"interrupted: {out_dir} left as it was")
        self.out_dir = out_dir


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
    figures: bool = True,
) -> tuple[dict[str, Any], Path]:
    """Run one scenario; returns its summary and its output folder ``<results_root>/<name>``.

    The scenario is loaded and validated before anything runs. The rerun recording goes to
    ``<out>/<name>.rrd`` (``record``); ``view`` also opens the viewer. ``figures=False`` asks
    the study to leave out its PNG figures (the studies whose ``run`` takes a ``figures``
    argument honour it; the numbers of the summary are the same either way). The folder is
    replaced whole or not at all (see :func:`replaced_whole`); Ctrl-C raises
    :class:`RunInterrupted`."""
    scenario = load_scenario(name_or_path)
    if scenario.study not in STUDIES:
        raise ScenarioError(
            f"{scenario.path}: unknown study '{scenario.study}'; known: {sorted(STUDIES)}"
        )
    run, report = _study(scenario.study)
    options = (
        {} if figures or "figures" not in inspect.signature(run).parameters else {"figures": False}
    )
    out_dir = Path(results_root or REPO_ROOT / "results") / scenario.name
    progress = Progress(scenario.name, quiet=quiet)
    try:
        with replaced_whole(out_dir) as work:
            rrd = work / f"{scenario.name}.rrd" if record else None
            with Recorder(rrd, f"pkm-calib-{scenario.name}", spawn_viewer=view) as recorder:
                recorder.send_blueprint()
                summary = run(scenario, work, progress, recorder, **options)
            if rrd is not None:
                summary["recording"] = rrd.name
            # paths into the run's folder as they are after the swap (its final name)
            summary = final_paths_in(summary)
            write_json_atomic(work / "summary.json", summary)
            write_text_atomic(work / "report.md", report(summary))
            name_final_paths(work)  # the files the command line wrote during the run
    except KeyboardInterrupt as exc:
        if isinstance(exc, RunInterrupted):
            raise
        raise RunInterrupted(out_dir) from exc
    progress.step(f"wrote {out_dir / 'summary.json'} and report.md")
    return summary, out_dir
