"""What the sweep test modules share (test_sweep, test_sweep_resume, test_sweep_ray)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import pytest

QUICK = ["plan.calibration_poses=30", "plan.test_poses=10"]  # undeclared_effect, seconds a run


def numbers(summary: dict[str, Any]) -> dict[str, Any]:
    """The aggregate's statistics without wall-clock times (which no engine reproduces)."""
    return {k: v for k, v in summary["metrics"].items() if "runtime" not in k}


@contextlib.contextmanager
def figures_off() -> Iterator[None]:
    """Sweeps in this process without figures: neither the sweep's distributions nor each
    run's diagnosis plot is drawn (nor its file written). For the sweeps whose numbers and
    files are what is checked; the Ray sweep and the last pass of the resumed sweep draw
    theirs, and test_scenario_undeclared_effect checks the diagnosis plot."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("scenarios.sweep.runner.distribution_pngs", lambda folder, name, results: [])
        mp.setattr(
            "scenarios.studies.undeclared_effect.study.save_diagnosis_png", lambda diag, path: path
        )
        yield
