"""A sweep interrupted after its first run resumes where it stopped; a run that fails is
counted, leaves its error, and does not stop the others; a third pass runs only the failed
ones again. (Its own module: ``make test`` runs it beside test_sweep.py.)"""

from __future__ import annotations

import pytest
from sweep_support import figures_off, numbers

from scenarios.sweep.runner import sweep


@pytest.mark.accuracy
def test_interrupted_sweep_resumes_and_a_failed_run_does_not_stop_the_others(tmp_path):
    sets = ["plan.calibration_poses=3,30", "plan.test_poses=10"]  # 3 poses: rank deficient
    seen = []

    def stop_after_first(result):
        seen.append(result["run_id"])
        if len(seen) == 1:
            raise KeyboardInterrupt

    with figures_off(), pytest.raises(KeyboardInterrupt):
        sweep(
            "undeclared_effect",
            2,
            "noise",
            sets,
            engine="local",
            results_root=tmp_path,
            quiet=True,
            on_result=stop_after_first,
        )
    with figures_off():
        s, out = sweep(
            "undeclared_effect", 2, "noise", sets, engine="local", results_root=tmp_path, quiet=True
        )
    assert s["n_runs"] == 4 and s["n_failed"] == 2
    failed = [r for r in s["runs"] if r["status"] == "failed"]
    assert all("IdentifiabilityError" in r["error"] for r in failed)
    assert all((out / r["run_id"] / "error.json").is_file() for r in failed)
    ok = [r for r in s["runs"] if r["status"] == "ok"]
    assert len(ok) == 2 and all((out / r["run_id"] / "summary.json").is_file() for r in ok)
    assert s["metrics"]["residual_rms_after_mm"]["n"] == 2
    assert list(s["by_setting"]) == ["plan.calibration_poses=30"]
    # a third pass runs only the failed ones again; finished runs are skipped
    s3, _ = sweep(
        "undeclared_effect", 2, "noise", sets, engine="local", results_root=tmp_path, quiet=True
    )
    assert sum(bool(r.get("resumed")) for r in s3["runs"]) == 2
    assert numbers(s3) == numbers(s)
