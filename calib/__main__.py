"""Command line for measured data: ``python -m calib identify --model M.xml --errors E.toml
--data readings.csv [--out result.json] [--fix-unidentifiable] [--sigma-mm S]`` and
``python -m calib diagnose ... --sigma-mm 0.005`` (is the residual more than noise, and which
effect is it).

Reads the nominal MJCF, the error model and a Dataset (CSV + JSON sidecar), reports which
parameters the poses can identify, estimates them robustly (gross outliers are rejected and
listed) and prints each with its standard error (mm, deg); ``--out`` writes the same as JSON
(atomically). A fit that did not converge or does not match the declared tracker accuracy
exits non-zero with the likely cause (exit codes in :mod:`calib.verdict`).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from calib.atomic_files import write_json_atomic
from calib.data_hints import likely_causes
from calib.dataset import Dataset, DatasetError, read_dataset
from calib.estimators.levenberg_marquardt import LMOptions
from calib.exceptions import CalibError
from calib.identify import (
    IdentificationResult,
    Observations,
    bind_dataset,
    identify,
    model_from_files,
)
from calib.model import CalibrationModel
from calib.position_error import error_norms, stats_mm
from calib.verdict import (
    DEFAULT_MAX_RATIO,
    EXIT_BAD_INPUT,
    EXIT_POOR_FIT,
    Verdict,
    declared_accuracy,
    implausible_estimates,
    judge_fit,
)
from twin.exceptions import TwinError


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (NaN, inf, 0 and negatives are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
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


def _kept_mask(result: IdentificationResult, shape: tuple[int, int]) -> np.ndarray:
    keep = np.ones(shape, dtype=bool)
    for r in getattr(result, "rejected", ()):
        keep[r.pose_index, r.target_index] = False
    return keep


def _rejected_rows(result: IdentificationResult, dataset: Dataset, obs_targets: tuple[str, ...]):
    return [
        {
            "pose_id": int(dataset.pose_ids[r.pose_index]),
            "target": obs_targets[r.target_index],
            "residual_mm": float(r.residual_m * 1e3),
        }
        for r in getattr(result, "rejected", ())
    ]


def fit_verdict(
    model: CalibrationModel,
    obs: Observations,
    result: IdentificationResult,
    dataset: Dataset,
    sigma_mm: float | None,
    max_ratio: float,
) -> tuple[Verdict, dict[str, Any]]:
    """The verdict on a fit and the 3D residual statistics of the kept readings."""
    pred = model.predict(result.values, obs.commands).targets
    norms = error_norms(obs.measured, pred)
    keep = _kept_mask(result, norms.shape)
    stats = stats_mm(norms[keep])
    accuracy = declared_accuracy(sigma_mm, dataset.tracker)
    message = getattr(result, "convergence_message", "") or (
        f"stopped after {result.iterations} iterations without the step or the cost change "
        "falling below its tolerance"
    )
    odd = implausible_estimates(
        result.names, model.params.to_display(result.values), model.params.is_angle
    )
    verdict = judge_fit(stats.rms_mm, result.converged, message, accuracy, max_ratio, (), odd)
    if not verdict.ok:
        hints = likely_causes(model, obs.commands, obs.measured, model.nominal.target_names)
        verdict = judge_fit(
            stats.rms_mm, result.converged, message, accuracy, max_ratio, tuple(hints), odd
        )
    return verdict, stats.as_dict()


def _print_verdict(verdict: Verdict) -> None:
    stream = sys.stdout if verdict.ok else sys.stderr
    print(verdict.message, file=stream)
    for hint in verdict.hints:
        print(f"  likely cause: {hint}", file=stream)


def _explain(model: CalibrationModel, obs: Observations, text: str) -> int:
    """Print the failure with the likely causes the data shows; exit 4 with a cause, else 2."""
    print(text, file=sys.stderr)
    hints = likely_causes(model, obs.commands, obs.measured, model.nominal.target_names)
    for hint in hints:
        print(f"  likely cause: {hint}", file=sys.stderr)
    return EXIT_POOR_FIT if hints else EXIT_BAD_INPUT


def _identify_or_explain(
    model: CalibrationModel,
    obs: Observations,
    unidentifiable: str,
    max_iterations: int | None,
) -> IdentificationResult | int:
    """The fit, or the exit code after explaining why there is none."""
    kwargs: dict[str, Any] = {"unidentifiable": unidentifiable}
    if max_iterations is not None:
        kwargs["options"] = LMOptions(max_iterations=max_iterations)
    try:
        return identify(model, obs, **kwargs)
    except _too_many_outliers() as exc:
        _explain(model, obs, f"FAILED: {exc}")
        return EXIT_POOR_FIT
    except TwinError as exc:
        return _explain(model, obs, f"error: the model cannot follow the data: {exc}")


def _too_many_outliers() -> tuple[type[Exception], ...]:
    from calib import exceptions

    cls = getattr(exceptions, "TooManyOutliersError", None)
    return (cls,) if cls is not None else ()


def cmd_identify(args: argparse.Namespace) -> int:
    model = model_from_files(args.model, args.errors)
    dataset = read_dataset(args.data, expected_model=model.nominal.name)
    obs = bind_dataset(model.nominal, dataset)
    result = _identify_or_explain(
        model, obs, "fix" if args.fix_unidentifiable else "raise", args.max_iterations
    )
    if isinstance(result, int):
        return result
    verdict, residual = fit_verdict(model, obs, result, dataset, args.sigma_mm, args.max_ratio)
    shown = model.params.to_display(result.values)
    std = model.params.to_display(result.std_errors)
    units = ["deg" if a else "mm" for a in model.params.is_angle]
    rejected = _rejected_rows(result, dataset, model.nominal.target_names)
    print(result.report.summary())
    print(
        f"3D position error per reading after the fit ({residual['n']} readings): "
        f"RMS {residual['rms_mm']:.4f} mm, mean {residual['mean_mm']:.4f} mm, "
        f"max {residual['max_mm']:.4f} mm; {result.iterations} iterations, "
        f"converged: {result.converged}"
    )
    if rejected:
        print(f"{len(rejected)} reading(s) rejected as gross outliers:")
        for row in rejected:
            print(
                f"  pose {row['pose_id']} target {row['target']}: "
                f"residual {row['residual_mm']:.3f} mm"
            )
    for name, v, s, u, est in zip(result.names, shown, std, units, result.estimated, strict=True):
        tail = f"+- {s:.4f}" if est else "(not identifiable: kept at 0)"
        print(f"  {name:32s} {v:+10.4f} {u:3s} {tail}")
    _print_verdict(verdict)
    if args.out:
        write_json_atomic(
            Path(args.out),
            {
                "model": model.nominal.name,
                "data": str(args.data),
                "n_poses": dataset.n_poses,
                "residual": residual,
                "residual_rms_mm": residual["rms_mm"],
                "converged": result.converged,
                "iterations": result.iterations,
                "verdict": verdict.as_dict(),
                "rejected": rejected,
                "n_identifiable": result.report.n_identifiable,
                "unidentifiable": result.report.unidentifiable,
                "parameters": {
                    n: {"value": float(v), "std": None if not e else float(s), "unit": u}
                    for n, v, s, u, e in zip(
                        result.names, shown, std, units, result.estimated, strict=True
                    )
                },
            },
        )
    return verdict.exit_code


def cmd_diagnose(args: argparse.Namespace) -> int:
    from calib.diagnosis import diagnose

    model = model_from_files(args.model, args.errors)
    dataset = read_dataset(args.data, expected_model=model.nominal.name)
    obs = bind_dataset(model.nominal, dataset)
    result = _identify_or_explain(model, obs, "fix", args.max_iterations)
    if isinstance(result, int):
        return result
    verdict, residual = fit_verdict(model, obs, result, dataset, args.sigma_mm, args.max_ratio)
    if not verdict.ok:
        print(
            "the geometric fit the diagnosis starts from is not usable; fix the data first",
            file=sys.stderr,
        )
        _print_verdict(verdict)
        return verdict.exit_code
    head = (dataset.tracker or {}).get("position_mm")
    diag = diagnose(
        model,
        obs,
        result,
        args.sigma_mm * 1e-3,
        order=dataset.order,
        tracker_position_m=None if head is None else np.asarray(head, dtype=float) * 1e-3,
    )
    print(
        f"geometric residual {diag.residual_rms_mm:.4f} mm RMS per coordinate; tracker noise "
        f"{diag.noise_floor_rms_mm:.4f} mm per coordinate; chi-square p = {diag.chi2_p_value:.3g}"
    )
    print(f"diagnosis: {diag.chosen} ({diag.reason})")
    for name, score in diag.scores.items():
        print(f"  {name:24s} held-out RMS {score.heldout_rms_mm:.5f} mm, BIC {score.bic:.1f}")
    if args.out:
        write_json_atomic(
            Path(args.out),
            {
                "residual": residual,
                "residual_rms_mm_per_coordinate": diag.residual_rms_mm,
                "noise_floor_rms_mm_per_coordinate": diag.noise_floor_rms_mm,
                "chi2_p_value": diag.chi2_p_value,
                "diagnosed_effect": diag.chosen,
                "reason": diag.reason,
                "rejected": _rejected_rows(result, dataset, model.nominal.target_names),
                "candidates": {n: s.heldout_rms_mm for n, s in diag.scores.items()},
                "effect_parameters": {n: v.tolist() for n, v in diag.coefficients.items()},
            },
        )
    return 0


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", required=True, help="nominal MJCF of the machine")
    p.add_argument("--errors", required=True, help="error model (TOML [[parameter]] list)")
    p.add_argument(
        "--max-ratio",
        type=ratio_float,
        default=DEFAULT_MAX_RATIO,
        help="fail (exit 4) when the 3D RMS residual exceeds this many times the noise the "
        f"tracker accuracy explains (default {DEFAULT_MAX_RATIO:g})",
    )
    p.add_argument("--out", help="write the result as JSON here (atomically)")
    p.add_argument(
        "--max-iterations",
        type=positive_int,
        help="stop the fit after this many iterations (exit 3 if it has not converged by then)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m calib",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True)
    ident = sub.add_parser("identify", help="identify geometric errors from a tracker dataset")
    _common(ident)
    ident.add_argument("--data", required=True, help="Dataset CSV (with its .json sidecar)")
    ident.add_argument(
        "--sigma-mm",
        type=positive_float,
        help="tracker accuracy per coordinate (mm); default: the sidecar's tracker.sigma_mm, "
        "else 0.05 mm assumed",
    )
    ident.add_argument(
        "--fix-unidentifiable",
        action="store_true",
        help="keep parameters the poses cannot identify at zero instead of stopping",
    )
    diag = sub.add_parser(
        "diagnose", help="test the residual of a geometric calibration for unmodelled effects"
    )
    _common(diag)
    diag.add_argument(
        "--data",
        required=True,
        help="Dataset CSV (rows in measurement order or with an 'order' column)",
    )
    diag.add_argument(
        "--sigma-mm",
        type=positive_float,
        required=True,
        help="tracker noise per coordinate (mm), e.g. from repeat readings",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "diagnose":
            return cmd_diagnose(args)
        return cmd_identify(args)
    except (DatasetError, CalibError, TwinError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
