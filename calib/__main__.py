"""Command line for measured data (any machine: serial, parallel or hybrid).

    python -m calib identify --model M.xml --errors E.toml --data D.csv [--set calibration]
                             [--out R.json] [--sigma-mm S] [--prior-std length=1,angle=0.1]
    python -m calib verify   --model M.xml --errors E.toml --result R.json --data D.csv
                             [--set test] [--out V.json]
    python -m calib diagnose --model M.xml --errors E.toml --data D.csv [--sigma-mm S]
                             [--test T.csv] [--out D.json]
    python -m calib compensate --model M.xml --errors E.toml --result R.json
                             --poses desired.csv --out commands.csv [--frame base|tracker]
    python -m calib export   --model M.xml --errors E.toml --result R.json
                             --out M_calibrated.xml [--dh-out T.csv]

``identify`` fits the error model to the readings of one set (default: the rows marked
'calibration', else all), robustly (gross outliers are rejected and listed), in the base
frame or, for a sidecar with "frame": "tracker", with the tracker's registration estimated
alongside. ``verify`` scores any set before (nominal) and after (identified): the 3D position
error per reading (RMS, mean, max), a per-reading CSV and a PNG. ``diagnose`` asks whether the
residual is more than the tracker noise and which physical effect explains it.
``compensate`` turns desired tool poses into the commands that put the identified machine
there; ``export`` writes the calibrated model (MJCF, and DH table for a DH-generated arm).
``verify --model M_calibrated.xml`` without ``--result`` scores a model as it is.

Exit codes (calib.verdict): 0 success; 2 bad input (the message names the cause); 3 the fit
did not converge; 4 the data does not fit the model (residual far above the declared tracker
accuracy, implausible estimates, or too many outliers; the likely cause is said);
5 some desired poses out of reach (compensate); 130 interrupted.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from calib import cmd_compensate, cmd_export
from calib.atomic_files import write_json_atomic, write_text_atomic
from calib.dataset import DatasetError, read_dataset
from calib.exceptions import CalibError
from calib.identify import model_from_files
from calib.prior import PriorSpec
from calib.result_file import load_result, write_result
from calib.verdict import (
    DEFAULT_MAX_RATIO,
    EXIT_BAD_INPUT,
    EXIT_OK,
    EXIT_POOR_FIT,
    Verdict,
)
from calib.workflow import (
    CalibrationRun,
    FitFailed,
    calibrate,
    rejected_rows,
    result_content,
    verify_result,
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


def prior_spec(text: str) -> PriorSpec:
    try:
        return PriorSpec.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _print_verdict(verdict: Verdict) -> None:
    stream = sys.stdout if verdict.ok else sys.stderr
    print(verdict.message, file=stream)
    for hint in verdict.hints:
        print(f"  likely cause: {hint}", file=stream)


def _failed(exc: FitFailed) -> int:
    print(f"FAILED: {exc}", file=sys.stderr)
    for hint in exc.hints:
        print(f"  likely cause: {hint}", file=sys.stderr)
    return EXIT_POOR_FIT if exc.poor_data else EXIT_BAD_INPUT


def _run(args: argparse.Namespace) -> CalibrationRun | int:
    model = model_from_files(args.model, args.errors)
    dataset = read_dataset(args.data, expected_model=model.nominal.name)
    try:
        return calibrate(
            model,
            dataset,
            set_name=args.set,
            sigma_mm=args.sigma_mm,
            max_ratio=args.max_ratio,
            max_iterations=args.max_iterations,
            unidentifiable="raise" if getattr(args, "require_all", False) else "fix",
            prior_spec=getattr(args, "prior_std", None),
        )
    except FitFailed as exc:
        return _failed(exc)


def _print_run(run: CalibrationRun) -> None:
    res, params = run.result, run.model.params
    print(run.selection)
    if run.model.nominal.masses_defaulted:
        print("the model declares no masses: MuJoCo's bounded defaults used (kinematics only)")
    print(res.report.summary())
    r = run.residual
    print(
        f"3D position error per reading after the fit ({r['n']} readings): RMS "
        f"{r['rms_mm']:.4f} mm, mean {r['mean_mm']:.4f} mm, max {r['max_mm']:.4f} mm; "
        f"{res.iterations} iterations, converged: {res.converged}"
    )
    rows = rejected_rows(run)
    if rows:
        print(f"{len(rows)} reading(s) rejected as gross outliers:")
        for row in rows:
            print(f"  pose {row['pose_id']} target {row['target']}: {row['residual_mm']:.3f} mm")
    if res.registration is not None:
        reg = res.registration.as_dict(res.registration_std)
        t, s = reg["translation_mm"], reg["std_translation_mm"]
        print(
            "tracker registration (tracker origin in the base frame): "
            + ", ".join(f"{v:.3f} +- {e:.4f}" for v, e in zip(t, s, strict=True))
            + " mm; rotation (rpy) "
            + ", ".join(f"{v:.4f}" for v in reg["rotation_rpy_deg"])
            + " deg"
        )
    shown, std = params.to_display(res.values), params.to_display(res.std_errors)
    weak = {w["name"] for w in run.weak}
    for name, v, s, ang, est in zip(
        res.names, shown, std, params.is_angle, res.estimated, strict=True
    ):
        unit = "deg" if ang else "mm"
        if est:
            tail = f"+- {s:.4f}" + ("  weakly identified" if name in weak else "")
        else:
            tail = f"(fixed at 0: {res.report.unidentifiable.get(name, 'not identifiable')})"
        print(f"  {name:32s} {v:+10.4f} {unit:3s} {tail}")
    if run.weak:
        print(
            f"{len(run.weak)} parameter(s) weakly identified (standard error above half the "
            "prior range); consider --prior-std or more poses over a larger volume"
        )
    for group in run.groups[:5]:
        print(f"  near-collinear (|r| > 0.95): {', '.join(group)}")


def cmd_identify(args: argparse.Namespace) -> int:
    run = _run(args)
    if isinstance(run, int):
        return run
    _print_run(run)
    _print_verdict(run.verdict)
    if args.out:
        write_result(args.out, result_content(run, args.model, args.errors, args.data))
    return run.verdict.exit_code


def _csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def cmd_verify(args: argparse.Namespace) -> int:
    if args.result is None:  # the model as it is, e.g. one written by export
        from calib import verify_as_is

        return verify_as_is.run(args)
    if args.errors is None:
        raise CalibError("verify --result needs --errors (the error model of the result)")
    model = model_from_files(args.model, args.errors)
    loaded = load_result(args.result, expected_model=model.nominal.name)
    dataset = read_dataset(args.data, expected_model=model.nominal.name)
    v, selection = verify_result(model, loaded, dataset, args.set)
    print(selection)
    print(v.note)
    for side in ("before", "after"):
        s = getattr(v, side)
        line = f"{side:6s}: 3D position error per reading {s.position.describe()}"
        if s.orientation_deg is not None:
            o = s.orientation_deg
            line += f"; orientation RMS {np.sqrt(np.mean(o * o)):.4f} deg, max {o.max():.4f} deg"
        print(line)
    if args.out:
        out = Path(args.out)
        content = {"result": str(args.result), "data": str(args.data), "set": args.set}
        write_json_atomic(out, {**content, **v.as_dict(), "selection": selection})
        write_text_atomic(out.with_suffix(".csv"), _csv_text(v.rows()))
        from calib.verify_figure import save_verification_png

        save_verification_png(v, out.with_suffix(".png"))
        print(f"wrote {out}, {out.with_suffix('.csv')} and {out.with_suffix('.png')}")
    return EXIT_OK


def _diagnosis_test_set(args: argparse.Namespace, run: CalibrationRun):
    """The --test file as a TestSet in the base frame (through the calibration's
    registration for tracker-frame data), or None."""
    from calib.diagnosis import TestSet
    from calib.identify import bind_dataset

    if not args.test:
        return None
    ds = read_dataset(args.test, expected_model=run.model.nominal.name)
    obs = bind_dataset(run.model.nominal, ds)
    if obs.frame != run.obs.frame:
        raise DatasetError(
            f"the test data is in the '{obs.frame}' frame but the calibration data in "
            f"'{run.obs.frame}'"
        )
    measured = obs.measured
    if run.result.registration is not None:
        measured = run.result.registration.to_base(measured)
    return TestSet(
        obs.commands,
        measured,
        None if ds.order is None else np.asarray(ds.order),
        None if ds.time_s is None else np.asarray(ds.time_s),
    )


def _typed_sigma_mm(args: argparse.Namespace, run: CalibrationRun) -> float | None:
    if args.sigma_mm is not None:
        return args.sigma_mm
    sigma = (run.dataset.tracker or {}).get("sigma_mm")
    return None if sigma is None else float(sigma)


def cmd_diagnose(args: argparse.Namespace) -> int:
    from calib.diagnosis import diagnose

    run = _run(args)
    if isinstance(run, int):
        return run
    if not run.verdict.ok:
        print(
            "the geometric fit the diagnosis starts from is not usable; fix the data first",
            file=sys.stderr,
        )
        _print_verdict(run.verdict)
        return run.verdict.exit_code
    head = (run.dataset.tracker or {}).get("position_mm")
    obs = run.obs
    if run.result.registration is not None:  # the diagnosis works in the base frame
        obs = replace(obs, measured=run.result.registration.to_base(obs.measured), frame="base")
    test = _diagnosis_test_set(args, run)
    typed = _typed_sigma_mm(args, run)
    ds = run.dataset
    if typed is None and ds.n_repeats < 2:
        raise DatasetError(
            "no noise level: give --sigma-mm, a sidecar tracker.sigma_mm, or data with repeats"
        )
    diag = diagnose(
        run.model,
        obs,
        run.result,
        None if typed is None else typed * 1e-3,
        order=ds.order,
        time_s=ds.time_s,
        repeat_std_m=ds.repeat_std if ds.n_repeats > 1 else None,
        n_repeats=ds.n_repeats,
        tracker_position_m=None if head is None else np.asarray(head, dtype=float) * 1e-3,
        test=test,
    )
    noise = diag.noise.as_dict() if diag.noise is not None else {}
    print(
        f"geometric residual {diag.residual_rms_mm:.4f} mm RMS per coordinate; noise "
        f"{diag.noise_floor_rms_mm:.4f} mm per coordinate ({noise.get('source', 'typed')}); "
        f"chi-square p = {diag.chi2_p_value:.3g}"
    )
    print(f"diagnosis: {diag.chosen} ({diag.reason})")
    for note in diag.notes:
        print(f"  note: {note}")
    for name, entry in diag.effect_parameters.items():
        for pname, v in entry.items():
            std = "" if v["std"] is None else f" +- {v['std']:.3g}"
            value = v["value"] if isinstance(v["value"], str) else f"{v['value']:.4g}"
            print(f"  {name}: {pname} = {value}{std} {v['unit']}")
    for name, score in diag.scores.items():
        tail = "" if score.test_rms_mm is None else f", test RMS {score.test_rms_mm:.5f} mm (3D)"
        refused = f"  REFUSED: {score.refused}" if score.refused else ""
        print(
            f"  {name:24s} held-out RMS blocked {score.heldout_blocked_mm:.5f} / random "
            f"{score.heldout_random_mm:.5f} mm{tail}{refused}"
        )
    if diag.test is not None:
        for side in ("before", "after"):
            t = diag.test[side]
            print(
                f"test {side:6s}: 3D position error per reading RMS {t['rms_mm']:.4f} mm, "
                f"mean {t['mean_mm']:.4f} mm, max {t['max_mm']:.4f} mm"
            )
    if args.out:
        out = Path(args.out)
        content = {
            "residual": run.residual,
            "residual_rms_mm_per_coordinate": diag.residual_rms_mm,
            "noise_floor_rms_mm_per_coordinate": diag.noise_floor_rms_mm,
            "noise": noise,
            "chi2_p_value": diag.chi2_p_value,
            "diagnosed_effect": diag.chosen,
            "reason": diag.reason,
            "notes": list(diag.notes),
            "rejected": rejected_rows(run),
            "candidates": {n: s.heldout_rms_mm for n, s in diag.scores.items()},
            "heldout_rms_mm_per_coordinate": diag.heldout,
            "refused": {n: s.refused for n, s in diag.scores.items() if s.refused},
            "effect_parameters": diag.effect_parameters,
            "residual_structure": diag.structure_detail,
            "metric": "3D position error per reading |p_measured - p_model| (mm)",
        }
        if diag.test is not None:
            content["test"] = {
                side: {k: diag.test[side][k] for k in ("rms_mm", "mean_mm", "max_mm")}
                for side in ("before", "after")
            }
        if diag.plot is not None:
            from calib.diagnosis_figure import save_diagnosis_png

            content["figure"] = str(save_diagnosis_png(diag, out.with_suffix(".png")))
        write_json_atomic(out, content)
    return EXIT_OK


def _model_options(p: argparse.ArgumentParser, errors_required: bool = True) -> None:
    p.add_argument("--model", required=True, help="nominal MJCF of the machine")
    p.add_argument(
        "--errors", required=errors_required, help="error model (TOML [[parameter]] list)"
    )
    p.add_argument("--data", required=True, help="Dataset CSV (with its .json sidecar)")
    p.add_argument("--out", help="write the result as JSON here (atomically)")


def _fit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--set",
        help="use the rows of this set (the 'set' column); default: the rows marked "
        "'calibration', or all rows when no row is",
    )
    p.add_argument(
        "--max-ratio",
        type=ratio_float,
        default=DEFAULT_MAX_RATIO,
        help="fail (exit 4) when the 3D RMS residual exceeds this many times the noise the "
        f"tracker accuracy explains (default {DEFAULT_MAX_RATIO:g})",
    )
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
    _model_options(ident)
    _fit_options(ident)
    ident.add_argument(
        "--sigma-mm",
        type=positive_float,
        help="tracker accuracy per coordinate (mm); default: the sidecar's tracker.sigma_mm, "
        "else 0.05 mm assumed",
    )
    ident.add_argument(
        "--prior-std",
        type=prior_spec,
        help="a Gaussian prior of zero mean on the errors, per kind: length=MM,angle=DEG "
        "(keeps weakly identified parameters physical)",
    )
    ident.add_argument(
        "--require-all",
        action="store_true",
        help="stop (exit 2) if the poses cannot identify every parameter, instead of keeping "
        "those at zero and saying why",
    )
    ident.add_argument(
        "--fix-unidentifiable",
        action="store_true",
        help="(the default now) keep unidentifiable parameters at zero",
    )
    ver = sub.add_parser("verify", help="score a dataset before and after a calibration")
    _model_options(ver, errors_required=False)
    ver.add_argument(
        "--result",
        help="result JSON written by identify --out; without it the model is scored as it is "
        "(e.g. one written by export), a tracker frame registered on the calibration rows",
    )
    ver.add_argument("--set", help="score the rows of this set (default: all rows)")
    diag = sub.add_parser(
        "diagnose", help="test the residual of a geometric calibration for unmodelled effects"
    )
    _model_options(diag)
    _fit_options(diag)
    diag.add_argument(
        "--sigma-mm",
        type=positive_float,
        help="tracker noise per coordinate (mm); default: from the repeat readings, else the "
        "sidecar's tracker.sigma_mm; a typed value is checked against the repeats",
    )
    diag.add_argument(
        "--test",
        help="a Dataset CSV of poses not used to fit: an effect is named only if it lowers "
        "their error too; the JSON gets test.before and test.after",
    )
    for command in (cmd_compensate, cmd_export):  # each subcommand in its own module
        command.add_parser(sub)
    return parser


COMMANDS = {
    "identify": cmd_identify,
    "verify": cmd_verify,
    "diagnose": cmd_diagnose,
    "compensate": cmd_compensate.run,
    "export": cmd_export.run,
}


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except (DatasetError, CalibError, TwinError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
