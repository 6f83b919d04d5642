"""What the command line's subcommands share: option types, the fit, the verdict's print."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from calib.correction import correction_in_file
from calib.data import CalibrationResult, Dataset, read_dataset, require_model
from calib.fit import (
    EXIT_BAD_INPUT,
    EXIT_OK,
    EXIT_POOR_FIT,
    MAX_SIGMA_MM,
    CalibrationRun,
    FitFailed,
    PriorSpec,
    Verdict,
    calibrate,
    model_from_files,
)
from calib.loop import extended_model, fit_with_diagnosis, load_effect


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


def run_fit(args: argparse.Namespace, dataset: Dataset | None = None) -> CalibrationRun | int:
    """Fit the ``--model``/``--errors`` error model to ``--data`` (``dataset``: that file,
    if the command has read it already), with ``--with`` a diagnosis's effect added."""
    model = model_from_files(args.model, args.errors)
    effect = getattr(args, "with_effect", None)
    diagnosis = None
    if effect:  # the effect a diagnosis named, as parameters of the error model
        correction = correction_in_file(effect, model)
        block = load_effect(effect, model, allow_empty=correction is not None)
        extended_model(model, block["added_parameters"], effect)  # its entries checked
        diagnosis = json.loads(Path(effect).read_text(encoding="utf-8"))
    if dataset is None:
        dataset = read_dataset(args.data, expected_model=model.nominal.name)
    else:
        require_model(args.data, dataset.model, model.nominal.name)
    options = fit_options(args)
    try:
        if diagnosis is not None:
            return fit_with_diagnosis(model, dataset, diagnosis, effect, options)
        return calibrate(model, dataset, **options)
    except FitFailed as exc:
        return failed(exc)


def fit_options(args: argparse.Namespace) -> dict:
    """calib.fit.calibrate's options from the command line's (identify's defaults where
    the command has no such option)."""
    return {
        "set_name": args.set,
        "sigma_mm": args.sigma_mm,
        "max_ratio": args.max_ratio,
        "max_iterations": args.max_iterations,
        "unidentifiable": "raise" if getattr(args, "require_all", False) else "fix",
        "prior_spec": getattr(args, "prior_std", None),
        "regularise": not getattr(args, "plain", False),
    }


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
