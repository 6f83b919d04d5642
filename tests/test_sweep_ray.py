"""A 4-run sweep on a local Ray (2 CPUs) gives the same numbers as the in-process engine.
(Its own module: ``make test`` runs it beside test_sweep.py.)"""

from __future__ import annotations

import json

import pytest
from sweep_support import QUICK, figures_off, numbers

from scenarios.sweep.runner import sweep


@pytest.mark.accuracy
def test_ray_sweep_on_two_cpus_matches_the_local_engine(tmp_path):
    ray = pytest.importorskip("ray")
    sets = [*QUICK, "tracker.sigma_mm=0.002,0.01"]
    with figures_off():  # the numbers to compare with; the Ray sweep draws its figures
        local, _ = sweep(
            "undeclared_effect",
            2,
            "noise",
            sets,
            engine="local",
            results_root=tmp_path / "local",
            quiet=True,
        )
    try:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        on_ray, out = sweep(
            "undeclared_effect",
            2,
            "noise",
            sets,
            engine="ray",
            results_root=tmp_path / "ray",
            quiet=True,
        )
    finally:
        ray.shutdown()
    assert on_ray["engine"] == "ray" and local["engine"] == "local"
    assert on_ray["n_runs"] == local["n_runs"] == 4
    assert on_ray["n_failed"] == local["n_failed"] == 0
    assert on_ray["swept"]["settings"] == {"tracker.sigma_mm": [0.002, 0.01]}
    # the same numbers to round-off: one BLAS thread in every run (scenarios.sweep.one_run)
    # on the same CPU, but a Ray worker is another process, whose kernels this test does
    # not pin; the same estimates to 1e-9 relative is what the engines promise
    assert _flat(numbers(on_ray)) == pytest.approx(_flat(numbers(local)), rel=1e-9, abs=1e-15)
    assert {k: _flat(numbers(g)) for k, g in on_ray["by_setting"].items()} == {
        k: pytest.approx(_flat(numbers(g)), rel=1e-9, abs=1e-15)
        for k, g in local["by_setting"].items()
    }
    for key in ("median", "p05", "p95", "mean", "std"):
        assert key in on_ray["metrics"]["residual_rms_after_mm"]
    # the noise floor follows the swept tracker sigma
    by = on_ray["by_setting"]
    assert (
        by["tracker.sigma_mm=0.002"]["metrics"]["noise_floor_rms_mm"]["median"]
        < by["tracker.sigma_mm=0.01"]["metrics"]["noise_floor_rms_mm"]["median"]
    )
    runs = json.loads((out / "summary.json").read_text())["runs"]
    assert all((out / r["run_id"] / "summary.json").is_file() for r in runs)
    assert (out / "report.md").read_text().count("![distributions]") >= 1
    assert (out / "undeclared_effect_sweep.rrd").stat().st_size > 0


def _flat(tree: dict, prefix: str = "") -> dict[str, float]:
    """Nested statistics as one level of numbers (key paths joined by '/')."""
    out: dict[str, float] = {}
    for k, v in tree.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}/"))
        else:
            out[f"{prefix}{k}"] = v
    return out
