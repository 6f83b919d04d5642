"""Sweeps: overrides checked like the file, seeds derived per run, a sweep over truths.
Resume and failures: test_sweep_resume.py; on Ray: test_sweep_ray.py (each its own module,
so that ``make test`` runs them beside this one)."""

from __future__ import annotations

from pathlib import Path

import pytest
from recording_faces import assert_every_face_has_data
from sweep_support import QUICK, figures_off

from scenarios.config import ScenarioError, load_scenario
from scenarios.sweep.aggregate import flatten_numbers, statistics
from scenarios.sweep.runner import sweep
from scenarios.sweep.settings import overridden, parse_set, parse_value, plan_runs, run_seeds

ROOT = Path(__file__).resolve().parent.parent


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
    text = (ROOT / "scenarios/studies/undeclared_effect/undeclared_effect.toml").read_text()
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
    with figures_off():
        s, out = sweep(
            str(path), 2, "truth", QUICK, engine="local", results_root=tmp_path, quiet=True
        )
    assert s["n_runs"] == 2 and s["n_failed"] == 0
    truths = [(out / r["run_id"] / "truth_values.toml").read_text() for r in s["runs"]]
    assert truths[0] != truths[1]
    # the sweep's recording: the runs on one timeline, every view with data on it
    assert_every_face_has_data(out / f"{out.parent.name}_sweep.rrd")
    assert {r["seeds"]["noise_seed"] for r in s["runs"]} == {7}
    # --over noise: one truth (the scenario's own seed's), noise seeds per run
    with figures_off():
        s, out = sweep(
            str(path), 2, "noise", QUICK, engine="local", results_root=tmp_path, quiet=True
        )
    truths = [(out / r["run_id"] / "truth_values.toml").read_text() for r in s["runs"]]
    assert truths[0] == truths[1]
