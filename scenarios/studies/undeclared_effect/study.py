"""Close the loop: the truth carries effects nobody declared; the diagnosis finds them.

The hexapod (Table 2 geometry) is measured with the effects of the scenario file switched on
in the truth. Calibration fits the geometry (LM), the diagnosis tests the residual against
the tracker noise, names the effect(s) from its library by held-out error and BIC, and the
model with the effect is scored against the geometric one on test poses that were not used
to fit (their pose as predicted from the commands against their measured pose).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.analysis import max_mean_stats, pose_errors_between
from calib.diagnosis import diagnose, effect_offsets, effect_target_shifts, save_diagnosis_png
from calib.fit import CalibrationModel, bind_dataset, identify
from scenarios.config import Scenario
from scenarios.files_loop import loop_through_files
from scenarios.loop_figures import effect_plots
from scenarios.machine_setup import build_effects, load_machine
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.twin_datasets import measured_dataset, through_file
from twin.kinematics import forward_batch
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

FIGURE = "diagnosis.png"  # the residual against the variable that explains it


def errors_3d(measured: np.ndarray, before: np.ndarray, after: np.ndarray) -> dict[str, dict]:
    """The 3D position error per reading on the test poses, before and after (mm)."""

    def stats(pred: np.ndarray) -> dict[str, float]:
        norms = np.linalg.norm(measured - pred, axis=-1) * 1e3
        return {
            "rms_mm": float(np.sqrt(np.mean(norms**2))),
            "mean_mm": float(np.mean(norms)),
            "max_mm": float(np.max(norms)),
        }

    return {"before": stats(before), "after": stats(after)}


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t0 = time.perf_counter()
    rng = np.random.default_rng(scenario.get("seed", int))
    machine = load_machine(scenario, rng)
    nominal, params, truth = machine.nominal, machine.params, machine.truth
    effects = build_effects(scenario)
    sigma = scenario.get("tracker.sigma_mm", float) * 1e-3
    tracker = Tracker(
        position_m=tuple(
            v * 1e-3 for v in scenario.get("tracker.position_mm", list, [1200.0, 0.0, 300.0])
        ),
        noise=TrackerNoise("gaussian", sigma, 0.0),
        scale_error=scenario.get("truth.tracker_scale_error", float, 0.0),
    )
    n_cal = scenario.get("plan.calibration_poses", int)
    n_test = scenario.get("plan.test_poses", int)
    poses, commands = random_poses(nominal, n_cal + n_test, rng)
    progress.step(f"measuring {n_cal} + {n_test} poses with {[e.name for e in effects]} on")
    order = np.arange(n_cal + n_test)  # one measurement sequence: calibration, then test
    from twin.measurement import measure

    m = measure(truth, commands, tracker, rng, effects=effects, order=order)
    model = CalibrationModel(nominal, params)
    sets = {}
    for name, sl in (("calibration", slice(0, n_cal)), ("test", slice(n_cal, None))):
        ds = measured_dataset(truth, commands[sl], poses[sl], name, tracker, rng)
        ds = type(ds)(**{**ds.__dict__, "readings": m.readings[sl], "order": order[sl]})
        ds = through_file(ds, out_dir / "datasets" / f"{name}.csv", nominal.name)
        sets[name] = (ds, bind_dataset(nominal, ds))
    cal_ds, cal = sets["calibration"]
    test_ds, test = sets["test"]

    progress.step("geometric calibration, then the residual diagnosis")
    result = identify(model, cal)
    head = np.asarray(cal_ds.tracker["position_mm"], dtype=float) * 1e-3
    diag = diagnose(
        model, cal, result, sigma, order=np.asarray(cal_ds.order), tracker_position_m=head
    )
    progress.note(f"{diag.chosen}: {diag.reason}")

    after_values = result.values.copy()
    if diag.geometry_correction is not None:
        after_values[result.estimated] += diag.geometry_correction
    local = nominal.target_local()
    timing = dict(time_origin=diag.time_origin, time_unit=diag.time_unit)

    def with_effects(
        commands: np.ndarray, order: np.ndarray, coef: dict[str, np.ndarray] | None = None
    ) -> np.ndarray:
        """Targets predicted with the named effects (``coef``, default all of them): actuator
        offsets through the kinematics, the effects on the readings (geometry beyond the
        error model, thermal expansion, tracker drift and scale) as the diagnosis fitted
        them."""
        coef = diag.coefficients if coef is None else coef
        shift = effect_offsets(model, after_values, commands, order, coef, **timing)
        pred = forward_batch(model.mechanism(after_values), commands + shift, check_stroke=False)
        return pred.targets + effect_target_shifts(
            model, result.values, commands, order, coef, tracker_position_m=head, **timing
        )

    before_pred = model.predict(result.values, test.commands).targets
    after_pred = with_effects(test.commands, np.asarray(test_ds.order))
    cal_after = with_effects(cal.commands, np.asarray(cal_ds.order))
    rms_before = float(
        np.sqrt(np.mean((cal.measured - model.predict(result.values, cal.commands).targets) ** 2))
    )
    rms_after = float(np.sqrt(np.mean((cal.measured - cal_after) ** 2)))
    figure = None
    if diag.plot is not None:
        save_diagnosis_png(diag, out_dir / FIGURE)
        figure = FIGURE
    recorder.log_mechanism(nominal)
    recorder.log_loop(
        nominal, cal_ds.order, model.predict(result.values, cal.commands), cal.measured, cal_after
    )
    if recorder.enabled:  # the cause: one view per named effect, against its variable
        cal_order = np.asarray(cal_ds.order)
        plots = effect_plots(
            model,
            after_values,
            cal.commands,
            cal_order,
            cal.measured,
            diag.coefficients,
            lambda coef: with_effects(cal.commands, cal_order, coef),
            **timing,
        )
        recorder.log_causes(diag, figure and out_dir / figure, plots, sigma * 1e3)
    recorder.log_verdict(diag, rms_before * 1e3, rms_after * 1e3, sigma * 1e3)
    summary = {
        "scenario": scenario.name,
        "model": nominal.name,
        "effects_in_truth": [e.name for e in effects],
        "residual_rms_before_mm": rms_before * 1e3,
        "residual_rms_after_mm": rms_after * 1e3,
        "noise_floor_rms_mm": sigma * 1e3,
        "chi2_p_value": diag.chi2_p_value,
        "diagnosed_effect": diag.chosen,
        "reason": diag.reason,
        "candidates": {n: s.heldout_rms_mm for n, s in diag.scores.items()},
        "figure": figure,
        "plot_variable": None if diag.plot is None else diag.plot["variable"],
        "test_3d": errors_3d(test.measured, before_pred, after_pred),
        "residual_structure": diag.structure,
        "effect_parameters": {n: v.tolist() for n, v in diag.coefficients.items()},
        "test": {
            "before": max_mean_stats(pose_errors_between(local, before_pred, test.measured)),
            "after": max_mean_stats(pose_errors_between(local, after_pred, test.measured)),
        },
    }
    progress.step("the same loop through the files: diagnose --out, identify --with, verify")
    summary["loop_through_files"] = loop_through_files(
        scenario.resolve(scenario.get("model", str), "model"),
        scenario.resolve(scenario.get("error_model", str), "error_model"),
        out_dir / "datasets" / "calibration.csv",
        out_dir / "loop_through_files",
        sigma * 1e3,
        test_data=out_dir / "datasets" / "test.csv",
    )
    summary["runtime_s"] = time.perf_counter() - t0
    recorder.log_report(scenario.study, summary)
    return summary
