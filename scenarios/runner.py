"""Runs a scenario by name or path and writes results/<name>/ (summary.json, report.md).

A results folder is replaced whole or not at all: the run writes into a temporary sibling
``results/.<name>.partial-XXXX`` and only at the end swaps it in for ``results/<name>``. On any
failure, Ctrl-C included, the temporary folder is removed and the previous results stay.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import os
import secrets
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from calib.atomic_files import write_json_atomic, write_text_atomic
from scenarios.config import REPO_ROOT, Scenario, ScenarioError, load_scenario
from scenarios.progress import Progress
from scenarios.recording import Recorder

StudyFn = Callable[[Scenario, Path, Progress, Recorder], dict[str, Any]]
ReportFn = Callable[[dict[str, Any]], str]

DIR_MODE = 0o755

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
    "serial_arm": ("scenarios.serial_arm", "scenarios.serial_arm_report"),
    "measured_loop": ("scenarios.measured_loop", "scenarios.measured_loop_report"),
    "diagnosis_benchmark": (
        "scenarios.diagnosis_benchmark",
        "scenarios.diagnosis_benchmark_report",
    ),
}


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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


KEPT = ("sweep",)  # subfolders of results/<name> that a plain run carries over


@contextlib.contextmanager
def replaced_whole(out_dir: Path) -> Iterator[Path]:
    """Yield an empty temporary sibling of ``out_dir`` to write into; when the block ends
    without an exception, it becomes ``out_dir`` (the previous folder renamed away, the new
    one renamed into place, the old one deleted; a ``sweep/`` folder of earlier sweeps is
    carried over). On any exception, KeyboardInterrupt included, the temporary folder is
    removed and ``out_dir`` is left untouched."""
    root = out_dir.parent
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=root))
    try:
        os.chmod(tmp, DIR_MODE & ~_umask())  # mkdtemp makes 0700; results are ordinary
        yield tmp
        for keep in KEPT:  # a sweep's runs are not this run's output: they stay
            if (out_dir / keep).is_dir() and not (tmp / keep).exists():
                os.rename(out_dir / keep, tmp / keep)
        old = None
        if out_dir.exists() or out_dir.is_symlink():
            old = root / f".{out_dir.name}.old-{secrets.token_hex(4)}"
            os.rename(out_dir, old)
        try:
            os.rename(tmp, out_dir)
        except BaseException:
            if old is not None:
                os.rename(old, out_dir)
            raise
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if old is not None:
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old, ignore_errors=True)
        else:
            old.unlink(missing_ok=True)


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
            write_json_atomic(work / "summary.json", summary)
            write_text_atomic(work / "report.md", report(summary))
    except KeyboardInterrupt as exc:
        if isinstance(exc, RunInterrupted):
            raise
        raise RunInterrupted(out_dir) from exc
    progress.step(f"wrote {out_dir / 'summary.json'} and report.md")
    return summary, out_dir
