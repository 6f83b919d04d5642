"""The path a user with measured data takes: select a set, identify, judge, keep, verify.

The command line (``pkm-calib``) and the scenarios call the same functions, so a twin
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
from calib.fit.fuller_model import FullerModel, fuller_or_not
from calib.fit.identification import IdentificationResult, identify
from calib.fit.kinds.state import state_for
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
from calib.fit.probe_rows import orientation_weight
from calib.fit.regularisation import PriorChoice, choose_prior
from calib.fit.verdict import (
    DEFAULT_MAX_RATIO,
    Accuracy,
    Verdict,
    implausible_estimates,
    judge_fit,
    noise_rule,
)
from calib.fit.verdict_notes import with_notes
from calib.fit.verify import Verification, nominal_fit_registration, verify
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
    fuller: FullerModel | None = None  # why the model carries parameters beyond the error model


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
    start: np.ndarray | None = None,
) -> CalibrationRun:
    """Identify from the rows of ``set_name`` (default: 'calibration' rows, else all),
    from the values ``start`` (SI; default zero: the nominal model).

    Directions of the parameters the data determine worse than their physical range are kept
    at zero, the rest estimated, where cross-validation over poses says that predicts held-out
    readings as well as plain least squares (calib.fit.regularisation); ``prior_spec``
    (``--prior-std``) instead puts a zero-mean prior of those widths, weighed against the
    data's own residual scale; ``regularise=False`` is plain least squares."""
    dataset = state_for(model, dataset)
    picked, selection = select_set(dataset, set_name, "calibration")
    used = set_name if set_name is not None else (CALIBRATION if picked is not dataset else None)
    obs = bind_dataset(model.nominal, picked)
    model.bind_state(obs.state)  # the offset kinds read the readings' state
    hints = _hints(model, obs)
    if hints:  # on the readings against the nominal model: its words never follow a fit's path
        raise FitFailed(
            f"{hints[0]} (found on the readings against the nominal model, before any fit: a "
            "fit of them is not usable); fix the data first",
            hints[1:],
            poor_data=True,
        )
    accuracy = noise_rule(sigma_mm, picked)  # declared, else the repeats, else assumed
    if obs.rotations is not None:  # 6-DoF probes: their rows weighed by the two accuracies
        weight = orientation_weight(accuracy.sigma_mm, picked.tracker)
        obs = replace(obs, orientation_weight_m=weight)
    options = None if max_iterations is None else LMOptions(max_iterations=max_iterations)
    starts = None if start is None else dict(zip(model.params.names, start, strict=True))
    fit = _Fitter(obs, unidentifiable, options, prior_spec, regularise, starts)
    result, choice = fit(model)
    # before readings are rejected as gross outliers: the error model's fuller variant
    model, result, choice, fuller = fuller_or_not(model, picked, obs, result, choice, fit)
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
        weak=weakly_identified(
            result.names, result.std_errors, model.params, prior_spec, result.values
        ),
        groups=collinear_groups(est_names, cov_k),
        correlations=correlation_pairs(est_names, cov_k),
        prior_spec=prior_spec,
        set_name=used,
        regularisation=choice,
        structure=structure,
        fuller=fuller,
    )


@dataclass(frozen=True)
class _Fitter:
    """One fit of a model to the selected observations, as :func:`calibrate` asks for it."""

    obs: Observations
    unidentifiable: str
    options: LMOptions | None
    prior_spec: PriorSpec | None
    regularise: bool
    starts: dict[str, float] | None = None  # start values by name (a fuller model: 0 else)

    def __call__(self, model: CalibrationModel) -> tuple[IdentificationResult, PriorChoice | None]:
        obs, unidentifiable, options = self.obs, self.unidentifiable, self.options
        start = None
        if self.starts is not None:
            start = np.array([self.starts.get(n, 0.0) for n in model.params.names])
        if model.state is None:
            model.bind_state(obs.state)
        if self.prior_spec is None:
            fitted = _identified(model, obs, unidentifiable, options, None, self.regularise, start)
            return fitted, None
        # the user's widths, weighed against the residual the data show
        ranges = physical_ranges(model.params, self.prior_spec)
        plain = _identified(model, obs, unidentifiable, options, None, False, start)
        free = plain.estimated
        choice = choose_prior(
            plain.fit_jacobian,
            plain.fit_residual,
            plain.values[free] - (0.0 if start is None else start[free]),
            ranges[free],
            plain.fit_pose_of_row,
            plain.fit_jacobian.shape[1],
            scales=(None, 1.0),
        )
        choice = replace(choice, scale=1.0)
        # gains and compliances free: the prior is on the geometry
        widths = np.where(np.asarray(model.params.is_geometric, bool), ranges, np.inf)
        prior = Prior(widths, choice.noise_sigma_m)
        return _identified(model, obs, unidentifiable, options, prior, False, start), choice


def _identified(
    model: CalibrationModel,
    obs: Observations,
    unidentifiable: str,
    options: LMOptions | None,
    prior: Prior | None,
    regularise: bool,
    start: np.ndarray | None = None,
) -> IdentificationResult:
    """:func:`identify` (weak directions kept at zero if ``regularise``), its failures as
    FitFailed with the likely causes."""
    try:
        return identify(
            model,
            obs,
            x0=start,
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
    # a named data error was looked for on the readings before the fit (calibrate): the
    # verdict on the fit itself names none
    verdict = judge_fit(
        stats.rms_mm,
        result.converged,
        message,
        accuracy,
        max_ratio,
        (),
        odd,
        reach_mm=float(np.max(np.linalg.norm(pred.targets, axis=-1))) * 1e3,
        structure=describe(structure),
    )
    return with_notes(verdict, result, *obs.measured.shape[:2]), stats.as_dict(), structure


def verify_result(
    model: CalibrationModel,
    loaded: CalibrationResult,
    dataset: Dataset,
    set_name: str | None,
) -> tuple[Verification, str]:
    """Score ``dataset`` (rows of ``set_name``, default all) before and after ``loaded``."""
    picked, selection = select_set(state_for(model, dataset), set_name, "verification")
    obs = bind_dataset(model.nominal, picked)
    model.bind_state(obs.state)
    values = loaded.values_for(model.params)
    frame = loaded.data.get("frame", "base")
    if obs.frame != frame:
        raise ResultFileError(
            f"the data is in the '{obs.frame}' frame but the result was identified from "
            f"'{frame}'-frame readings: a registration cannot carry over"
        )
    before = None
    if obs.frame == "tracker":
        if loaded.registration is None:
            raise ResultFileError(f"{loaded.path}: tracker-frame result without registration")
        before = nominal_registration(model, loaded)
    try:
        v = verify(
            model,
            values,
            obs.commands,
            obs.measured,
            picked.pose_ids,
            registration_after=loaded.registration,
            registration_before=before,
            rotations=obs.rotations,
        )
    except TwinError as exc:  # e.g. no closure at the result's values: name the odd ones
        raise unusable_values(loaded, model.params, exc) from None
    return v, selection


def nominal_registration(model: CalibrationModel, loaded: CalibrationResult):
    """The nominal model's registration on the result's calibration set (the rows the result
    names in the data file it names): the one frame every command's "before" uses (verify's
    nominal side, compensate's nominal commands). None for a base-frame result, or when the
    calibration set is not readable."""
    if loaded.data.get("frame", "base") != "tracker":
        return None
    calibration = _calibration_set(model, loaded)
    return None if calibration is None else nominal_fit_registration(model, *calibration)


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
