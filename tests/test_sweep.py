"""Sweeps: overrides checked like the file, seeds derived per run, resume, failures, and a
4-run sweep on a local Ray (2 CPUs) that gives the same numbers as the in-process engine."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from scenarios.config import ScenarioError, load_scenario
from scenarios.sweep import sweep
from scenarios.sweep_aggregate import flatten_numbers, statistics
from scenarios.sweep_settings import overridden, parse_set, parse_value, plan_runs, run_seeds

ROOT = Path(__file__).resolve().parent.parent
QUICK = ["plan.calibration_poses=30", "plan.test_poses=10"]  # undeclared_effect, ~1.5 s a run


def _numbers(summary: dict) -> dict:
    """The aggregate's statistics without wall-clock times (which no engine reproduces)."""
    return {k: v for k, v in summary["metrics"].items() if "runtime" not in k}


def test_set_values_are_toml_or_text():
    assert parse_set("tracker.sigma_mm=0.002,0.005,0.01") == (
        "tracker.sigma_mm",
        [0.002, 0.005, 0.01],
    )
    assert parse_set("tracker.position_mm=[0, 0, 1],[1,2,3]")[1] == [[0, 0, 1], [1, 2, 3]]
    assert parse_value("gaussian") == "gaussian" and parse_value("true") is True
    with pytest.raises(ScenarioError, match="key=value"):
        parse_set("tracker.sigma_mm")
    with pytest.raises(ScenarioError, match="cannot be overridden"):
        parse_set("study=serial_arm")


def test_overrides_are_validated_like_the_file():
    s = load_scenario("undeclared_effect")
    assert overridden(s, {"tracker.sigma_mm": 0.01}).data["tracker"]["sigma_mm"] == 0.01
    assert s.data["tracker"]["sigma_mm"] == 0.005  # the loaded scenario is left as it was
    with pytest.raises(ScenarioError, match=r"'tracker.sigma_mm' must be >= 0"):
        overridden(s, {"tracker.sigma_mm": -1.0})
    with pytest.raises(ScenarioError, match=r"unknown key 'tracker.sigma'; did you mean"):
        overridden(s, {"tracker.sigma": 0.01})


def test_seeds_per_run_do_not_depend_on_the_count_and_over_is_checked():
    assert run_seeds(7, 5)[:3] == run_seeds(7, 3)
    assert len({t for t, _ in run_seeds(7, 50)}) == 50
    fixed_truth = load_scenario("undeclared_effect")  # truth from a values file
    runs = plan_runs(fixed_truth, 3, "noise", {"tracker.sigma_mm": [0.002, 0.005]})
    assert len(runs) == 6 and len({r.run_id for r in runs}) == 6
    assert {r.overrides["seed"] for r in runs} == {n for _, n in run_seeds(7, 3)}
    assert all(r.truth_seed is None for r in runs)
    with pytest.raises(ScenarioError, match="--over truth needs"):
        plan_runs(fixed_truth, 2, "truth", {})
    with pytest.raises(ScenarioError, match="use --over both"):
        plan_runs(load_scenario("serial_arm"), 2, "noise", {})
    with pytest.raises(ScenarioError, match="must be >= 1"):
        plan_runs(fixed_truth, 2, "both", {"plan.test_poses": [0, 5]})


def test_statistics_and_flattening():
    s = statistics([1.0, 2.0, 3.0, 4.0])
    assert s["median"] == 2.5 and s["mean"] == 2.5 and s["n"] == 4
    assert s["p05"] == pytest.approx(1.15) and s["p95"] == pytest.approx(3.85)
    assert s["std"] == pytest.approx(1.2909944487)
    flat = flatten_numbers({"a": {"b": 1, "c": True, "d": [1, 2]}, "e": 2.5, "f": None})
    assert flat == {"a.b": 1.0, "e": 2.5}


def _random_truth_copy(tmp_path: Path) -> Path:
    text = (ROOT / "scenarios/undeclared_effect.toml").read_text()
    text = text.replace(
        'values_file = "truth/hexapod_table2.toml"',
        "random = { translation_mm = 0.3 }",
    )
    path = tmp_path / "random_truth.toml"
    path.write_text(text)
    return path


@pytest.mark.accuracy
def test_over_truth_holds_the_noise_and_draws_each_truth(tmp_path):
    path = _random_truth_copy(tmp_path)
    s, out = sweep(str(path), 2, "truth", QUICK, engine="local", results_root=tmp_path, quiet=True)
    assert s["n_runs"] == 2 and s["n_failed"] == 0
    truths = [(out / r["run_id"] / "truth_values.toml").read_text() for r in s["runs"]]
    assert truths[0] != truths[1]
    assert {r["seeds"]["noise_seed"] for r in s["runs"]} == {7}
    # --over noise: one truth (the scenario's own seed's), noise seeds per run
    s, out = sweep(str(path), 2, "noise", QUICK, engine="local", results_root=tmp_path, quiet=True)
    truths = [(out / r["run_id"] / "truth_values.toml").read_text() for r in s["runs"]]
    assert truths[0] == truths[1]


@pytest.mark.accuracy
def test_interrupted_sweep_resumes_and_a_failed_run_does_not_stop_the_others(tmp_path):
    sets = ["plan.calibration_poses=3,30", "plan.test_poses=10"]  # 3 poses: rank deficient
    seen = []

    def stop_after_first(result):
        seen.append(result["run_id"])
        if len(seen) == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
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
    assert _numbers(s3) == _numbers(s)


@pytest.mark.accuracy
def test_ray_sweep_on_two_cpus_matches_the_local_engine(tmp_path):
    ray = pytest.importorskip("ray")
    sets = [*QUICK, "tracker.sigma_mm=0.002,0.01"]
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
    differ = {
        k: (v, local["metrics"].get(k))
        for k, v in _numbers(on_ray).items()
        if v != _numbers(local).get(k)
    }
    assert not differ, differ
    assert {k: _numbers(g) for k, g in on_ray["by_setting"].items()} == {
        k: _numbers(g) for k, g in local["by_setting"].items()
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
