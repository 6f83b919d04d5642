"""Command line for measured data: ``python -m calib identify --model M.xml --errors E.toml
--data readings.csv [--out result.json] [--fix-unidentifiable]`` and ``python -m calib
diagnose ... --sigma-mm 0.005`` (is the residual more than noise, and which effect is it).

Reads the nominal MJCF, the error model and a Dataset (CSV + JSON sidecar), reports which
parameters the poses can identify, estimates them by Levenberg-Marquardt and prints each
with its standard error (mm, deg); ``--out`` writes the same as JSON (atomically).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from calib.atomic_files import write_json_atomic
from calib.dataset import DatasetError, read_dataset
from calib.exceptions import CalibError
from calib.identify import bind_dataset, identify, model_from_files
from twin.exceptions import TwinError


def cmd_identify(args: argparse.Namespace) -> int:
    model = model_from_files(args.model, args.errors)
    dataset = read_dataset(args.data, expected_model=model.nominal.name)
    obs = bind_dataset(model.nominal, dataset)
    result = identify(model, obs, unidentifiable="fix" if args.fix_unidentifiable else "raise")
    shown = model.params.to_display(result.values)
    std = model.params.to_display(result.std_errors)
    units = ["deg" if a else "mm" for a in model.params.is_angle]
    print(result.report.summary())
    print(
        f"residual RMS {result.residual_rms * 1e3:.4f} mm per coordinate, "
        f"{result.iterations} iterations, converged: {result.converged}"
    )
    for name, v, s, u, est in zip(result.names, shown, std, units, result.estimated, strict=True):
        tail = f"+- {s:.4f}" if est else "(not identifiable: kept at 0)"
        print(f"  {name:32s} {v:+10.4f} {u:3s} {tail}")
    if args.out:
        write_json_atomic(
            Path(args.out),
            {
                "model": model.nominal.name,
                "data": str(args.data),
                "n_poses": dataset.n_poses,
                "residual_rms_mm": result.residual_rms * 1e3,
                "converged": result.converged,
                "iterations": result.iterations,
                "n_identifiable": result.report.n_identifiable,
                "unidentifiable": result.report.unidentifiable,
                "parameters": {
                    n: {"value": float(v), "std": None if not e else float(s), "unit": u}
                    for n, v, s, u, e in zip(
                        result.names,
                        shown,
                        np.nan_to_num(std),
                        units,
                        result.estimated,
                        strict=True,
                    )
                },
            },
        )
    return 0


def cmd_diagnose(args: argparse.Namespace) -> int:
    from calib.diagnosis import diagnose

    model = model_from_files(args.model, args.errors)
    dataset = read_dataset(args.data, expected_model=model.nominal.name)
    obs = bind_dataset(model.nominal, dataset)
    result = identify(model, obs, unidentifiable="fix")
    order = dataset.order if dataset.order is not None else None
    head = (dataset.tracker or {}).get("position_mm")
    diag = diagnose(
        model,
        obs,
        result,
        args.sigma_mm * 1e-3,
        order=order,
        tracker_position_m=None if head is None else np.asarray(head, dtype=float) * 1e-3,
    )
    print(
        f"geometric residual {diag.residual_rms_mm:.4f} mm RMS per coordinate; tracker noise "
        f"{diag.noise_floor_rms_mm:.4f} mm; chi-square p = {diag.chi2_p_value:.3g}"
    )
    print(f"diagnosis: {diag.chosen} ({diag.reason})")
    for name, score in diag.scores.items():
        print(f"  {name:24s} held-out RMS {score.heldout_rms_mm:.5f} mm, BIC {score.bic:.1f}")
    if args.out:
        write_json_atomic(
            Path(args.out),
            {
                "residual_rms_mm": diag.residual_rms_mm,
                "noise_floor_rms_mm": diag.noise_floor_rms_mm,
                "chi2_p_value": diag.chi2_p_value,
                "diagnosed_effect": diag.chosen,
                "reason": diag.reason,
                "candidates": {n: s.heldout_rms_mm for n, s in diag.scores.items()},
                "effect_parameters": {n: v.tolist() for n, v in diag.coefficients.items()},
            },
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m calib", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    ident = sub.add_parser("identify", help="identify geometric errors from a tracker dataset")
    ident.add_argument("--model", required=True, help="nominal MJCF of the machine")
    ident.add_argument("--errors", required=True, help="error model (TOML [[parameter]] list)")
    ident.add_argument("--data", required=True, help="Dataset CSV (with its .json sidecar)")
    ident.add_argument("--out", help="write the result as JSON here")
    ident.add_argument(
        "--fix-unidentifiable",
        action="store_true",
        help="keep parameters the poses cannot identify at zero instead of stopping",
    )
    diag = sub.add_parser(
        "diagnose", help="test the residual of a geometric calibration for unmodelled effects"
    )
    diag.add_argument("--model", required=True, help="nominal MJCF of the machine")
    diag.add_argument("--errors", required=True, help="error model (TOML [[parameter]] list)")
    diag.add_argument(
        "--data",
        required=True,
        help="Dataset CSV (rows in measurement order or with an 'order' column)",
    )
    diag.add_argument(
        "--sigma-mm",
        type=float,
        required=True,
        help="tracker noise per coordinate (mm), e.g. from repeat readings",
    )
    diag.add_argument("--out", help="write the diagnosis as JSON here")
    args = parser.parse_args(argv)
    try:
        if args.command == "diagnose":
            return cmd_diagnose(args)
        return cmd_identify(args)
    except (DatasetError, CalibError, TwinError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
