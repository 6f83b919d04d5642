"""The path a user with measured data takes: select a set, identify, judge, keep, verify.

The command line (``python -m calib``) and the scenarios call the same functions, so a twin
scenario exercises exactly what a real export goes through.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from calib.analysis.rank_structure import describe, pose_probes, rank_correlations
from calib.data.dataset import Dataset
from calib.data.dataset_io import read_dataset
from calib.data.hints import likely_causes
from calib.data.result_file import (
    CalibrationResult,
    ResultFileError,
    correlation_pairs,
    unusable_values,
)
from calib.data.select import CALIBRATION, select_set
from calib.estimators.levenberg_marquardt import LMOptions
from calib.exceptions import CalibError, TooManyOutliersError
from calib.fit.identification import IdentificationResult, identify
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations, bind_dataset
from calib.fit.position_error import stats_mm
from calib.fit.prior import (
    Prior,
    PriorSpec,
    collinear_groups,
    physical_ranges,
    weakly_identified,
)
from calib.fit.probe_rows import orientation_weight, probe_line
from calib.fit.regularisation import PriorChoice, choose_prior, cut_label
from calib.fit.verdict import (
    DEFAULT_MAX_RATIO,
    Accuracy,
    Verdict,
    declared_accuracy,
    implausible_estimates,
    judge_fit,
)
from calib.fit.verdict_notes import with_notes
from calib.fit.verify import Verification, probe_deg, verify
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
    regularisation: PriorChoice | None = None  # the user's prior (--prior-std), if any
    structure: dict[str, dict] = field(default_factory=dict)  # rank correlations of the residual


def calibrate(
    model: CalibrationModel,
    dataset: Dataset,
    set_name: str | None = None,
    sigma_mm: float | None = None,
    max_ratio: float | None = DEFAULT_MAX_RATIO,
    max_iterations: int | None = None,
    unidentifiable: str = "fix",
    prior_spec: PriorSpec | None = None,
    regularise: bool = True,
) -> CalibrationRun:
    """Identify from the rows of ``set_name`` (default: 'calibration' rows, else all).

    Directions of the parameters the data determine worse than their physical range are kept
    at zero, the rest estimated, where cross-validation over poses says that predicts held-out
    readings as well as plain least squares (calib.fit.regularisation); ``prior_spec``
    (``--prior-std``) instead puts a zero-mean prior of those widths, weighed against the
    data's own residual scale; ``regularise=False`` is plain least squares."""
    picked, selection = select_set(dataset, set_name, "calibration")
    used = set_name if set_name is not None else (CALIBRATION if picked is not dataset else None)
    obs = bind_dataset(model.nominal, picked)
    accuracy = declared_accuracy(sigma_mm, picked.tracker)
    if obs.rotations is not None:  # 6-DoF probes: their rows weighed by the two accuracies
        weight = orientation_weight(accuracy.sigma_mm, picked.tracker)
        obs = replace(obs, orientation_weight_m=weight)
    options = None if max_iterations is None else LMOptions(max_iterations=max_iterations)
    ranges = physical_ranges(model.params, prior_spec)
    choice = None
    if prior_spec is None:
        result = _identified(model, obs, unidentifiable, options, None, regularise)
    else:  # the user's widths, weighed against the residual the data show
        plain = _identified(model, obs, unidentifiable, options, None, False)
        free = plain.estimated
        choice = choose_prior(
            plain.fit_jacobian,
            plain.fit_residual,
            plain.values[free],
            ranges[free],
            plain.fit_pose_of_row,
            plain.fit_jacobian.shape[1],
            scales=(None, 1.0),
        )
        choice = replace(choice, scale=1.0)
        # gains and compliances free: the prior is on the geometry
        widths = np.where(np.asarray(model.params.is_geometric, bool), ranges, np.inf)
        prior = Prior(widths, choice.noise_sigma_m)
        result = _identified(model, obs, unidentifiable, options, prior, False)
    try:
        verdict, residual, structure = judge(model, obs, result, accuracy, max_ratio, picked)
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
        weak=weakly_identified(result.names, result.std_errors, model.params, prior_spec),
        groups=collinear_groups(est_names, cov_k),
        correlations=correlation_pairs(est_names, cov_k),
        prior_spec=prior_spec,
        set_name=used,
        regularisation=choice,
        structure=structure,
    )


def _identified(
    model: CalibrationModel,
    obs: Observations,
    unidentifiable: str,
    options: LMOptions | None,
    prior: Prior | None,
    regularise: bool,
) -> IdentificationResult:
    """:func:`identify` (weak directions kept at zero if ``regularise``), its failures as
    FitFailed with the likely causes."""
    try:
        return identify(
            model,
            obs,
            unidentifiable=unidentifiable,
            options=options,
            prior=prior,
            subspace="auto" if regularise else "full",
        )
    except TooManyOutliersError as exc:
        raise FitFailed(str(exc), _hints(model, obs), poor_data=True) from None
    except TwinError as exc:  # a closure that does not solve for these data
        hints = _hints(model, obs)
        raise FitFailed(
            f"the model cannot follow the data: {exc}", hints, poor_data=bool(hints)
        ) from None


def _hints(model: CalibrationModel, obs: Observations) -> list[str]:
    return likely_causes(
        model, obs.commands, obs.measured, model.nominal.target_names, frame=obs.frame
    )


def judge(
    model: CalibrationModel,
    obs: Observations,
    result: IdentificationResult,
    accuracy: Accuracy,
    max_ratio: float | None,
    dataset: Dataset | None = None,
) -> tuple[Verdict, dict[str, Any], dict[str, dict]]:
    """The verdict on a fit, the 3D residual statistics of its kept readings, and the rank
    correlations of each pose's residual size with the pose variables."""
    measured = (
        obs.measured if result.registration is None else result.registration.to_base(obs.measured)
    )
    pred = model.predict(result.values, obs.commands)
    norms = np.linalg.norm(measured - pred.targets, axis=-1)
    keep = np.ones(norms.shape, dtype=bool)
    for r in result.rejected:
        if r.target_index < keep.shape[1]:  # beyond: a probe's orientation (its point kept)
            keep[r.pose_index, r.target_index] = False
    stats = stats_mm(norms[keep])
    message = result.convergence_message or (
        f"stopped after {result.iterations} iterations without the step or the cost change "
        "falling below its tolerance"
    )
    params = model.params
    odd = implausible_estimates(
        result.names,
        params.to_display(result.values),
        params.display_units(),
        params.to_display(np.nan_to_num(result.std_errors)),
    )
    count = np.maximum(keep.sum(axis=1), 1)
    size = np.sqrt(np.sum(np.where(keep, norms, 0.0) ** 2, axis=1) / count)
    order = np.arange(len(size)) if dataset is None or dataset.order is None else dataset.order
    probes = pose_probes(obs.commands, model.nominal.actuator_names, pred.targets.mean(1), order)
    structure = rank_correlations(size, probes)
    noise = np.sqrt(3.0) * accuracy.sigma_mm
    # a data error shows as a residual above the noise, or (in a tracker's frame, where a
    # registration and shrunken links can follow readings in metres) as implausible estimates
    hints = tuple(_hints(model, obs)) if stats.rms_mm > 2.0 * noise or odd else ()
    verdict = judge_fit(
        stats.rms_mm,
        result.converged,
        message,
        accuracy,
        max_ratio,
        hints,
        odd,
        reach_mm=float(np.max(np.linalg.norm(pred.targets, axis=-1))) * 1e3,
        structure=describe(structure),
    )
    return with_notes(verdict, result, *obs.measured.shape[:2]), stats.as_dict(), structure


def probe_summary(run: CalibrationRun) -> str:
    """The line identify prints of 6-DoF readings (calib.fit.probe_rows.probe_line)."""
    res, obs = run.result, run.obs
    pred = run.model.predict(res.values, obs.commands)
    deg = probe_deg(run.model, res.values, pred.qpos, obs.rotations, res.registration)
    sigma_deg = float((run.dataset.tracker or {})["sigma_deg"])
    return probe_line(obs, run.verdict.accuracy.sigma_mm, sigma_deg, deg)


def rejected_rows(run: CalibrationRun) -> list[dict[str, Any]]:
    """The rejected readings by the dataset's pose_id and target name, residual in mm."""
    names = list(run.model.nominal.target_names)
    if run.obs.rotations is not None:  # a probe's orientation is a reading of its own
        oriented = np.isfinite(run.obs.rotations).all(axis=(0, 2, 3))
        names += [f"{n} (orientation)" for n, o in zip(names, oriented, strict=True) if o]
    return [
        {
            "pose_id": int(run.dataset.pose_ids[r.pose_index]),
            "target": names[r.target_index],
            "residual_mm": float(r.residual_m * 1e3),
        }
        for r in run.result.rejected
    ]


def result_content(run: CalibrationRun, model_path: str, errors_path: str, data_path: str):
    """Everything the result file holds (see calib.data.result_file)."""
    res, params = run.result, run.model.params
    shown = params.to_display(res.values)
    std = params.to_display(res.std_errors)
    units = params.display_units()
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
        "prior": prior_content(run),
        "regularisation": regularisation_content(run),
        "residual_structure": run.structure,
        "weakly_identified": run.weak,
        "near_collinear_groups": run.groups,
        "correlations_above_0.9": run.correlations,
        "parameters": parameters,
    }


def prior_content(run: CalibrationRun) -> dict[str, Any] | None:
    """The prior the kept fit used, in file units, and where its widths came from."""
    choice = run.regularisation
    if choice is None or choice.scale is None:
        return None
    ranges = physical_ranges(run.model.params, run.prior_spec)
    is_angle = np.asarray(run.model.params.is_angle, dtype=bool)
    is_length = ~is_angle & np.asarray(run.model.params.is_geometric, dtype=bool)
    length = float(ranges[is_length][0]) * 1e3 * choice.scale if is_length.any() else None
    angle = float(np.degrees(ranges[is_angle][0])) * choice.scale if is_angle.any() else None
    return {
        "length_mm": length,
        "angle_deg": angle,
        "source": "--prior-std" if run.prior_spec is not None else "cross-validated default",
        "weighed_against_mm_per_coordinate": choice.noise_sigma_m * 1e3,
    }


def regularisation_content(run: CalibrationRun) -> dict[str, Any]:
    """What the result file says of the weak directions: the choice and its numbers."""
    sub, choice = run.result.subspace, run.regularisation
    out: dict[str, Any] = {"text": regularisation_text(run)}
    if choice is not None:
        out.update(method="zero-mean prior (--prior-std)", **choice.as_dict())
    elif sub is not None:
        out.update(sub.as_dict())
    else:
        out["method"] = "plain least squares"
    return out


def regularisation_text(run: CalibrationRun) -> str:
    """What was regularised, in a sentence made of the run's numbers."""
    sub, choice = run.result.subspace, run.regularisation
    if choice is not None:  # the user's prior
        prior = prior_content(run) or {}
        widths = ", ".join(
            f"{v:.3g} {u}"
            for v, u in ((prior.get("length_mm"), "mm"), (prior.get("angle_deg"), "deg"))
            if v is not None
        )
        cv = choice.cv_rms_mm
        held = ""
        if "none" in cv and choice.label in cv:
            held = (
                f"; {choice.folds}-fold cross-validated 3D RMS {cv[choice.label]:.4f} mm with "
                f"it, {cv['none']:.4f} mm without"
            )
        return (
            f"prior (--prior-std): zero mean, {widths}, weighed against the data's residual "
            f"of {choice.noise_sigma_m * 1e3:.4f} mm per coordinate{held}"
        )
    if sub is None:
        return "plain least squares over every identifiable parameter"
    weak = (
        f"{sub.n_weak} direction(s) of the parameters the data determine worse than their "
        f"physical range (at the data's residual of {sub.noise_sigma_m * 1e3:.4f} mm per "
        "coordinate)"
    )
    cv = sub.cv_rms_mm
    if sub.cut is None:
        if not cv:
            return f"plain least squares: {weak}"
        return (
            f"plain least squares: {weak}; keeping them at zero would predict held-out poses "
            f"worse ({sub.folds}-fold cross-validated 3D RMS {cv['none']:.4f} mm plain, "
            + ", ".join(f"{k} {v:.4f} mm" for k, v in cv.items() if k != "none")
            + ")"
        )
    return (
        f"regularised: {sub.n_frozen} of {weak} kept at zero (minimum norm), the rest "
        f"estimated; {sub.folds}-fold cross-validated 3D RMS {cv[cut_label(sub.cut)]:.4f} mm, "
        f"plain least squares {cv['none']:.4f} mm"
    )


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
            rotations=obs.rotations,
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
