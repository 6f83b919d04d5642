"""The path a user with measured data takes: select a set, identify, judge, keep, verify.

The command line (``python -m calib``) and the scenarios call the same functions, so a twin
scenario exercises exactly what a real export goes through.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calib.data_hints import likely_causes
from calib.dataset import Dataset, read_dataset
from calib.dataset_select import CALIBRATION, select_set
from calib.estimators.levenberg_marquardt import LMOptions
from calib.exceptions import CalibError, TooManyOutliersError
from calib.identify import IdentificationResult, Observations, bind_dataset, identify
from calib.model import CalibrationModel
from calib.position_error import stats_mm
from calib.prior import Prior, PriorSpec, collinear_groups, weakly_identified
from calib.result_file import (
    CalibrationResult,
    ResultFileError,
    correlation_pairs,
    unusable_values,
)
from calib.verdict import (
    DEFAULT_MAX_RATIO,
    Accuracy,
    Verdict,
    declared_accuracy,
    implausible_estimates,
    judge_fit,
)
from calib.verdict_notes import with_notes
from calib.verify import Verification, verify
from twin.exceptions import TwinError


class FitFailed(CalibError):
    """No estimate: too many outliers, or a model that cannot follow the data."""

    def __init__(self, message: str, hints: list[str], poor_data: bool) -> None:
        super().__init__(message)
        self.hints = hints
        self.poor_data = poor_data


@dataclass(frozen=True)
class CalibrationRun:
    model: CalibrationModel
    dataset: Dataset  # the selected poses
    selection: str  # which rows were used, in words
    obs: Observations
    result: IdentificationResult
    verdict: Verdict
    residual: dict[str, Any]  # 3D error per kept reading: n, rms_mm, mean_mm, max_mm
    weak: list[dict] = field(default_factory=list)
    groups: list[list[str]] = field(default_factory=list)
    correlations: list[dict] = field(default_factory=list)
    prior_spec: PriorSpec | None = None
    set_name: str | None = None


def calibrate(
    model: CalibrationModel,
    dataset: Dataset,
    set_name: str | None = None,
    sigma_mm: float | None = None,
    max_ratio: float = DEFAULT_MAX_RATIO,
    max_iterations: int | None = None,
    unidentifiable: str = "fix",
    prior_spec: PriorSpec | None = None,
) -> CalibrationRun:
    """Identify from the rows of ``set_name`` (default: 'calibration' rows, else all)."""
    picked, selection = select_set(dataset, set_name, "calibration")
    used = set_name if set_name is not None else (CALIBRATION if picked is not dataset else None)
    obs = bind_dataset(model.nominal, picked)
    accuracy = declared_accuracy(sigma_mm, picked.tracker)
    prior = None
    if prior_spec is not None:
        prior = Prior(prior_spec.std_si(model.params.is_angle), accuracy.sigma_mm * 1e-3)
    options = None if max_iterations is None else LMOptions(max_iterations=max_iterations)
    try:
        result = identify(model, obs, unidentifiable=unidentifiable, options=options, prior=prior)
    except TooManyOutliersError as exc:
        raise FitFailed(str(exc), _hints(model, obs), poor_data=True) from None
    except TwinError as exc:  # a closure that does not solve for these data
        hints = _hints(model, obs)
        raise FitFailed(
            f"the model cannot follow the data: {exc}", hints, poor_data=bool(hints)
        ) from None
    try:
        verdict, residual = judge(model, obs, result, accuracy, max_ratio)
    except TwinError as exc:  # the estimate went where the machine does not close
        raise FitFailed(
            f"the fit wandered off: at its estimate the model does not close at the data's "
            f"commands ({exc})",
            _hints(model, obs),
            poor_data=True,
        ) from None
    cov_k = result.covariance[: int(result.estimated.sum()), : int(result.estimated.sum())]
    est_names = tuple(n for n, e in zip(result.names, result.estimated, strict=True) if e)
    return CalibrationRun(
        model=model,
        dataset=picked,
        selection=selection,
        obs=obs,
        result=result,
        verdict=verdict,
        residual=residual,
        weak=weakly_identified(result.names, result.std_errors, model.params.is_angle, prior_spec),
        groups=collinear_groups(est_names, cov_k),
        correlations=correlation_pairs(est_names, cov_k),
        prior_spec=prior_spec,
        set_name=used,
    )


def _hints(model: CalibrationModel, obs: Observations) -> list[str]:
    return likely_causes(
        model, obs.commands, obs.measured, model.nominal.target_names, frame=obs.frame
    )


def judge(
    model: CalibrationModel,
    obs: Observations,
    result: IdentificationResult,
    accuracy: Accuracy,
    max_ratio: float,
) -> tuple[Verdict, dict[str, Any]]:
    """The verdict on a fit and the 3D residual statistics of its kept readings."""
    norms = result.residuals_m(model, obs)
    keep = np.ones(norms.shape, dtype=bool)
    for r in result.rejected:
        keep[r.pose_index, r.target_index] = False
    stats = stats_mm(norms[keep])
    message = result.convergence_message or (
        f"stopped after {result.iterations} iterations without the step or the cost change "
        "falling below its tolerance"
    )
    odd = implausible_estimates(
        result.names, model.params.to_display(result.values), model.params.is_angle
    )
    verdict = judge_fit(stats.rms_mm, result.converged, message, accuracy, max_ratio, (), odd)
    if not verdict.ok:
        verdict = judge_fit(
            stats.rms_mm,
            result.converged,
            message,
            accuracy,
            max_ratio,
            tuple(_hints(model, obs)),
            odd,
        )
    return with_notes(verdict, result, *obs.measured.shape[:2]), stats.as_dict()


def rejected_rows(run: CalibrationRun) -> list[dict[str, Any]]:
    """The rejected readings by the dataset's pose_id and target name, residual in mm."""
    names = run.model.nominal.target_names
    return [
        {
            "pose_id": int(run.dataset.pose_ids[r.pose_index]),
            "target": names[r.target_index],
            "residual_mm": float(r.residual_m * 1e3),
        }
        for r in run.result.rejected
    ]


def result_content(run: CalibrationRun, model_path: str, errors_path: str, data_path: str):
    """Everything the result file holds (see calib.result_file)."""
    res, params = run.result, run.model.params
    shown = params.to_display(res.values)
    std = params.to_display(res.std_errors)
    units = ["deg" if a else "mm" for a in params.is_angle]
    reasons = res.report.unidentifiable
    parameters = {}
    for n, v, s, u, e in zip(res.names, shown, std, units, res.estimated, strict=True):
        entry: dict[str, Any] = {"value": float(v), "unit": u}
        if e:
            entry.update(status="estimated", std=float(s))
        else:
            entry.update(status="fixed", std=None, reason=reasons.get(n, "fixed"))
        parameters[n] = entry
    reg = None
    if res.registration is not None:
        reg = res.registration.as_dict(res.registration_std)
    return {
        "model": run.model.nominal.name,
        "model_file": str(model_path),
        "errors_file": str(errors_path),
        "data": str(data_path),
        "set": run.set_name,
        "selection": run.selection,
        "frame": run.obs.frame,
        "units": {"length": "mm", "angle": "deg"},
        "n_poses": run.dataset.n_poses,
        "masses_defaulted": run.model.nominal.masses_defaulted,
        "residual": run.residual,
        "residual_rms_mm": run.residual["rms_mm"],
        "metric": "3D position error per reading |p_measured - p_model| (mm)",
        "converged": res.converged,
        "convergence": res.convergence_message,
        "iterations": res.iterations,
        "verdict": run.verdict.as_dict(),
        "rejected": rejected_rows(run),
        "robust_scale_mm_per_coordinate": res.robust_scale_m * 1e3,
        "n_identifiable": res.report.n_identifiable,
        "unidentifiable": reasons,
        "redundant_with_registration": list(res.redundant_with_registration),
        "registration": reg,
        "prior": None if run.prior_spec is None else run.prior_spec.as_dict(),
        "weakly_identified": run.weak,
        "near_collinear_groups": run.groups,
        "correlations_above_0.9": run.correlations,
        "parameters": parameters,
    }


def verify_result(
    model: CalibrationModel,
    loaded: CalibrationResult,
    dataset: Dataset,
    set_name: str | None,
) -> tuple[Verification, str]:
    """Score ``dataset`` (rows of ``set_name``, default all) before and after ``loaded``."""
    picked, selection = select_set(dataset, set_name, "verification")
    obs = bind_dataset(model.nominal, picked)
    values = loaded.values_for(model.params)
    frame = loaded.data.get("frame", "base")
    if obs.frame != frame:
        raise ResultFileError(
            f"the data is in the '{obs.frame}' frame but the result was identified from "
            f"'{frame}'-frame readings: a registration cannot carry over"
        )
    calibration = None
    if obs.frame == "tracker":
        if loaded.registration is None:
            raise ResultFileError(f"{loaded.path}: tracker-frame result without registration")
        calibration = _calibration_set(model, loaded)
    try:
        v = verify(
            model,
            values,
            obs.commands,
            obs.measured,
            picked.pose_ids,
            registration_after=loaded.registration,
            calibration_set=calibration,
        )
    except TwinError as exc:  # e.g. no closure at the result's values: name the odd ones
        raise unusable_values(loaded, model.params, exc) from None
    return v, selection


def _calibration_set(model: CalibrationModel, loaded: CalibrationResult):
    """(commands, readings) of the result's calibration set, or None if not readable."""
    path = loaded.data.get("data")
    if not path or not Path(path).is_file():
        return None
    try:
        ds = read_dataset(path, expected_model=model.nominal.name)
        picked, _ = select_set(ds, loaded.data.get("set"), "calibration")
        obs = bind_dataset(model.nominal, picked)
    except (CalibError, ValueError, OSError):
        return None
    return obs.commands, obs.measured
