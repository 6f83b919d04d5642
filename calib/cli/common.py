"""What the command line's subcommands share: option types, the fit, the verdict's print."""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from calib.correction import correction_in_file, held_dataset
from calib.data import CalibrationResult, Dataset, read_dataset
from calib.fit import (
    EXIT_BAD_INPUT,
    EXIT_OK,
    EXIT_POOR_FIT,
    MAX_SIGMA_MM,
    CalibrationModel,
    CalibrationRun,
    FitFailed,
    PriorSpec,
    Verdict,
    calibrate,
    model_from_files,
)
from calib.loop import extended_model, load_effect


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (NaN, inf, 0 and negatives are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def sigma_float(text: str) -> float:
    """argparse type: a tracker accuracy in mm, finite, > 0 and at most MAX_SIGMA_MM."""
    value = positive_float(text)
    if value > MAX_SIGMA_MM:
        raise argparse.ArgumentTypeError(
            f"{value:g} mm is beyond {MAX_SIGMA_MM:g} mm: no measuring system of a machine is "
            "that coarse (the value is in millimetres per coordinate)"
        )
    return value


def ratio_float(text: str) -> float:
    value = positive_float(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a number >= 1, got {text!r}")
    return value


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


def prior_spec(text: str) -> PriorSpec:
    try:
        return PriorSpec.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def print_verdict(verdict: Verdict) -> None:
    stream = sys.stdout if verdict.ok else sys.stderr
    print(verdict.message, file=stream)
    for hint in verdict.hints:
        print(f"  likely cause: {hint}", file=stream)


def failed(exc: FitFailed) -> int:
    print(f"FAILED: {exc}", file=sys.stderr)
    for hint in exc.hints:
        print(f"  likely cause: {hint}", file=sys.stderr)
    return EXIT_POOR_FIT if exc.poor_data else EXIT_BAD_INPUT


def run_fit(args: argparse.Namespace) -> CalibrationRun | int:
    model = model_from_files(args.model, args.errors)
    base = model
    effect = getattr(args, "with_effect", None)
    correction = None
    if effect:  # the effect a diagnosis named, as parameters of the error model
        correction = correction_in_file(effect, model)
        block = load_effect(effect, model, allow_empty=correction is not None)
        model = extended_model(model, block["added_parameters"], effect)
    dataset = read_dataset(args.data, expected_model=model.nominal.name)
    options = {
        "set_name": args.set,
        "sigma_mm": args.sigma_mm,
        "max_ratio": args.max_ratio,
        "max_iterations": args.max_iterations,
        "unidentifiable": "raise" if getattr(args, "require_all", False) else "fix",
        "prior_spec": getattr(args, "prior_std", None),
        "regularise": not getattr(args, "plain", False),
    }
    try:
        if correction is not None:  # the diagnosis's residual correction, held in the fit
            dataset = _held(base, dataset, correction, options, effect)
        start = None
        if model.n_parameters > base.n_parameters:
            start, model = _geometric_start(base, model, dataset, options, effect)
        return calibrate(model, dataset, start=start, **options)
    except FitFailed as exc:
        return failed(exc)


def _held(base: CalibrationModel, dataset: Dataset, correction, options: dict, where: str):
    """``dataset``'s readings less the residual correction of the diagnosis ``where`` at
    each pose (its features from the geometric fit; said)."""
    geo = calibrate(base, dataset, **{**options, "max_ratio": None})
    held, inside = held_dataset(
        dataset, correction, geo.model, geo.result.values, geo.result.registration
    )
    print(
        f"residual correction of {where} held: the readings less it at {inside} of "
        f"{dataset.n_poses} poses (the others outside the calibrated region), the geometry"
        " and any named effect refitted to what is left"
    )
    return held


def _geometric_start(
    base: CalibrationModel,
    model: CalibrationModel,
    dataset: Dataset,
    options: dict,
    effect: str,
) -> tuple[np.ndarray | None, CalibrationModel]:
    """The start of a fit with a diagnosed effect: the geometric fit's estimate, where the
    diagnosis formed the effect's columns (an added parameter can move the readings there
    and not at the nominal model: a joint with the nominal reflector on its axis), the added
    parameters at zero; None (the nominal start) when the geometric fit is refused. And the
    model to fit: the geometric fit's own (the error model's fuller variant when identify
    kept it, calib.fit.fuller_model) with the effect's parameters."""
    geo = calibrate(base, dataset, **{**options, "max_ratio": None})
    if not geo.verdict.ok:
        return None, model
    if geo.model.n_parameters != base.n_parameters:  # the fuller geometry, and the effect
        model = extended_model(geo.model, load_effect(effect, geo.model)["added_parameters"])
        added = ", ".join(geo.model.params.names[base.n_parameters :])
        print(f"the geometry as identify kept it: the error model and {added}")
    names = list(model.params.names)
    start = np.zeros(model.n_parameters)
    for name, value in zip(geo.result.names, geo.result.values, strict=True):
        start[names.index(name)] = value
    print(
        f"start: the geometric fit's estimate ({geo.residual['rms_mm']:.4f} mm RMS), the "
        f"{model.n_parameters - geo.model.n_parameters} added parameters at zero"
    )
    return start, model


def result_options(p: argparse.ArgumentParser) -> None:
    """The nominal model, its error model and a result of identify: what a command that
    starts from a calibration (compensate, export) reads."""
    p.add_argument("--model", required=True, help="nominal MJCF of the machine")
    p.add_argument("--errors", required=True, help="error model (TOML [[parameter]] list)")
    p.add_argument("--result", required=True, help="result JSON written by identify --out")
    p.add_argument(
        "--force",
        action="store_true",
        help="use a result that identify refused (exit 3 or 4) anyway, and say so",
    )


def identify_exit_code(result: CalibrationResult) -> int:
    """The exit code identify gave ``result`` (0 if it was accepted or does not say)."""
    code = (result.data.get("verdict") or {}).get("exit_code", EXIT_OK)
    return code if isinstance(code, int) and not isinstance(code, bool) else EXIT_OK


def refused_result(result: CalibrationResult, force: bool, command: str) -> int:
    """identify's exit code for a result it refused, said with its reason on stderr, for
    ``command`` to return before writing anything; 0 for an accepted result, or with
    ``force`` (then the refusal is said and the command proceeds)."""
    code = identify_exit_code(result)
    if code == EXIT_OK:
        return EXIT_OK
    verdict = result.data.get("verdict") or {}
    message = str(verdict.get("message", "")).strip() or "(no reason recorded)"
    if force:
        print(
            f"--force: {command} of {result.path}, a result identify refused (exit {code}): "
            f"{message}",
            file=sys.stderr,
        )
        return EXIT_OK
    print(
        f"REFUSED RESULT: identify refused {result.path} (exit {code}): {message}",
        file=sys.stderr,
    )
    for hint in verdict.get("hints") or []:
        print(f"  likely cause: {hint}", file=sys.stderr)
    print(
        f"{command}: nothing written; fix the fit (identify's message above), or --force to "
        f"{command} this result anyway",
        file=sys.stderr,
    )
    return code
