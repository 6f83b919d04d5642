"""A serial arm measured by a tracker standing in its own frame: exactly a user's path.

The truth twin is the generic 6R arm (models/arm6r*, from a modified-DH table, no masses)
with a seeded draw of DH errors. A laser tracker 4-6 m away, turned about its vertical axis,
reports the reflector(s) in its own frame. The study writes one dataset file holding a
calibration and a test set, then runs the user's commands on it, in process:

    pkm-calib identify --model M --errors E --data D --set calibration --out R.json
    pkm-calib verify   --model M --errors E --result R.json --data D --set test --out V.json

once with one reflector (positions only) and once with three, then closes the loop through
``compensate``, ``export`` and ``verify`` of the exported model (scenarios.studies.serial_arm.loop).
The numbers come from the files those commands write.
"""

from __future__ import annotations

import contextlib
import io
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calib.cli import main as calib_main
from calib.data import load_result, write_dataset
from calib.fit import Registration
from scenarios.config import Scenario, ScenarioError
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.results_folder import final_paths
from scenarios.studies.serial_arm.loop import close_the_loop
from scenarios.truth_draw import TruthSpec, draw_truth
from scenarios.twin_datasets import tracker_frame_dataset
from twin.formats import load_parameter_set
from twin.kinematics import forward_batch
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import uniform_commands


def _tracker(scenario: Scenario) -> Tracker:
    return Tracker(
        position_m=tuple(v * 1e-3 for v in scenario.get("tracker.position_mm", list)),
        noise=TrackerNoise.from_spec(scenario.get("tracker.noise", str)),
        rotation_rpy_rad=tuple(np.radians(scenario.get("tracker.rotation_deg", list))),
    )


def _cli(args: list[str], log: Path) -> int:
    """Run ``pkm-calib ...`` in process; its output goes to ``log``."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = calib_main(args)
    # the paths as they are after the run's folder is swapped in (scenarios.results_folder)
    log.write_text(final_paths(f"$ pkm-calib {' '.join(args)}\n{out.getvalue()}exit {code}\n"))
    return code


def _registration_error_mm(estimated: Registration, tracker: Tracker, readings: np.ndarray):
    """RMS distance between where the estimated and the true tracker frames put the
    readings: what the registration gets wrong, including the base errors it absorbs."""
    rot, t = tracker.base_from_tracker
    true_base = np.asarray(readings).reshape(-1, 3) @ rot.T + t
    est_base = estimated.to_base(np.asarray(readings).reshape(-1, 3))
    return float(np.sqrt(np.mean(np.sum((est_base - true_base) ** 2, axis=1))) * 1e3)


POSE_TIMELINE = "pose"  # the pose number in the dataset, both variants


@dataclass(frozen=True)
class DrawnArm:
    """An arm of the scenario's files, its drawn truth and its commands (calibration, then
    test poses), with the accuracy its export declares."""

    model: Path
    errors: Path
    nominal: Mechanism
    params: ParameterSet
    truth: Mechanism
    commands: np.ndarray
    n_cal: int
    n_test: int
    sigma_mm: float


def drawn_arm(
    scenario: Scenario, model_key: str, errors_key: str, rng: np.random.Generator
) -> DrawnArm:
    """The arm of ``model_key`` / ``errors_key`` with a truth drawn from ``truth.random`` and
    joint commands over ``plan.joint_fraction`` of each range (in that order from ``rng``)."""
    model_path = scenario.resolve(scenario.get(model_key, str), model_key)
    errors_path = scenario.resolve(scenario.get(errors_key, str), errors_key)
    nominal = Mechanism.from_xml(model_path)
    params = load_parameter_set(errors_path, nominal.model)
    truth_values = draw_truth(params, TruthSpec.from_scenario(scenario), rng)
    truth = nominal.with_model(params.inject(nominal.model, truth_values))
    n_cal = scenario.get("plan.calibration_poses", int)
    n_test = scenario.get("plan.test_poses", int)
    commands = uniform_commands(
        nominal, n_cal + n_test, scenario.get("plan.joint_fraction", float), rng
    )
    sigma_mm = scenario.get("tracker.sigma_mm", float)
    return DrawnArm(
        Path(model_path),
        Path(errors_path),
        nominal,
        params,
        truth,
        commands,
        n_cal,
        n_test,
        sigma_mm,
    )


def _variant(
    scenario: Scenario,
    name: str,
    model_key: str,
    errors_key: str,
    out_dir: Path,
    rng: np.random.Generator,
    progress: Progress,
    recorder: Recorder,
) -> dict[str, Any]:
    arm = drawn_arm(scenario, model_key, errors_key, rng)
    model_path, errors_path, nominal, params = arm.model, arm.errors, arm.nominal, arm.params
    truth, commands, n_cal, n_test = arm.truth, arm.commands, arm.n_cal, arm.n_test
    tracker, sigma_mm = _tracker(scenario), arm.sigma_mm
    (out_dir / "datasets").mkdir(parents=True, exist_ok=True)
    data = write_dataset(
        tracker_frame_dataset(
            truth,
            tracker,
            commands,
            n_cal,
            sigma_mm,
            rng,
            notes="twin: generic 6R arm, tracker in its own frame",
        ),
        out_dir / "datasets" / f"{name}.csv",
    )
    result_json, verify_json = out_dir / f"{name}_result.json", out_dir / f"{name}_verify.json"
    common = ["--model", str(model_path), "--errors", str(errors_path), "--data", str(data)]
    progress.step(f"{name}: identify --set calibration, verify --set test")
    code_id = _cli(
        ["identify", *common, "--set", "calibration", "--out", str(result_json)],
        out_dir / f"{name}_identify.log",
    )
    if not result_json.is_file():  # the log goes with the run's folder: its words, here
        said = (out_dir / f"{name}_identify.log").read_text().strip().splitlines()
        raise ScenarioError(
            f"{name}: identify exited {code_id} without a result; it said:\n  "
            + "\n  ".join(said[-12:])
        )
    code_ver = _cli(
        [
            "verify",
            *common,
            "--result",
            str(result_json),
            "--set",
            "test",
            "--out",
            str(verify_json),
        ],
        out_dir / f"{name}_verify.log",
    )
    result = json.loads(result_json.read_text())
    ver = json.loads(verify_json.read_text())
    loaded = load_result(result_json, expected_model=nominal.name)
    from calib.data import read_dataset

    readings = read_dataset(data).readings.mean(axis=2)
    calibrated = nominal.with_model(params.inject(nominal.model, loaded.values_for(params)))
    fk = forward_batch(calibrated, commands)
    # both variants on one timeline (a second would be a face where the other's view is
    # empty), each arm under its own name; the reflectors' error magnified to be seen
    recorder.log_mechanism(nominal, machine=name)
    shown = np.arange(0, len(commands), max(1, len(commands) // 20))
    recorder.log_poses(
        POSE_TIMELINE,
        shown,
        calibrated,
        fk.qpos[shown],
        fk.targets[shown],
        np.array([loaded.registration.to_base(readings[k]) for k in shown]),
        name.replace("_", " "),
        machine=name,
    )
    progress.step(f"{name}: compensate, re-measure, export, verify the exported model")
    loop = close_the_loop(
        scenario,
        name,
        model_path,
        errors_path,
        data,
        result_json,
        truth,
        calibrated,
        tracker,
        out_dir,
        _cli,
    )
    return {
        **loop,
        "n_poses": {"calibration": n_cal, "test": n_test},
        "n_targets": nominal.n_targets,
        "exit_codes": {"identify": code_id, "verify": code_ver},
        "calibration": result["residual"],
        "test": {"before": ver["before"], "after": ver["after"]},
        "registration_error_mm": _registration_error_mm(loaded.registration, tracker, readings),
        "tracker_distance_mm": float(np.linalg.norm(tracker.position_m) * 1e3),
        "n_parameters": len(params),
        "n_identifiable": result["n_identifiable"],
        "redundant_with_registration": result["redundant_with_registration"],
        "unidentifiable": result["unidentifiable"],
        "weakly_identified": [w["name"] for w in result["weakly_identified"]],
        "verdict": result["verdict"]["message"],
        "noise_floor_3d_mm": float(np.sqrt(3) * sigma_mm),
        "masses_defaulted": result["masses_defaulted"],
    }


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t0 = time.perf_counter()
    rng = np.random.default_rng(scenario.get("seed", int))
    one = _variant(
        scenario, "one_reflector", "model", "error_model", out_dir, rng, progress, recorder
    )
    three = _variant(
        scenario,
        "three_reflectors",
        "variants.three_reflectors.model",
        "variants.three_reflectors.error_model",
        out_dir,
        rng,
        progress,
        recorder,
    )
    summary = {
        "study": "serial_arm",
        **one,
        "variants": {"three_reflectors": three},
        "runtime_s": time.perf_counter() - t0,
    }
    recorder.log_report("serial_arm", summary)
    return summary
