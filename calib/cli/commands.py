"""Command line for measured data (any machine: serial, parallel or hybrid).

    pkm-calib identify --model M.xml --errors E.toml --data D.csv [--set calibration]
                       [--out R.json] [--sigma-mm S] [--plain | --prior-std SPEC]
                       [--with D.json]
    pkm-calib verify   --model M.xml --errors E.toml --result R.json --data D.csv
                       [--set test] [--register | --register-set NAME]
                       [--iso9283] [--out V.json]
    pkm-calib diagnose --model M.xml --errors E.toml --data D.csv [--set calibration]
                       [--sigma-mm S] [--test-set test] [--test T.csv] [--out D.json]
    pkm-calib compensate --model M.xml --errors E.toml --result R.json
                       (--commands program.csv | --poses desired.csv [--seed ...])
                       --out commands.csv [--frame base|tracker] [--force]
    pkm-calib export   --model M.xml --errors E.toml --result R.json
                       --out M_calibrated.xml [--dh-out T.csv]
    pkm-calib plan     --model M.xml --errors E.toml --n N --out program.csv
                       [--candidates FILE] [--tracker-at X,Y,Z] [--predict]

``identify`` fits the error model to the readings of one set (default: the rows marked
'calibration', else all), robustly (gross outliers are rejected and listed), in the base
frame or, for a sidecar with "frame": "tracker", with the tracker's registration estimated
alongside; directions the data determine worse than their physical range are kept at zero
where that predicts held-out poses no worse (``--plain``: never). ``--with D.json`` adds the
effect a diagnosis named to the error model. ``verify`` scores any set before (nominal) and
after (identified): the 3D position error per reading (RMS, mean, max), a per-reading CSV and
a PNG. ``diagnose`` asks whether the residual is more than the tracker noise and which
physical effect explains it, judged on held-out poses. ``compensate`` turns a robot's
program (joint targets) or desired tool poses into the commands that put the identified
machine's tool where they mean; ``export`` writes the
calibrated model (MJCF; DH table for a DH-generated arm); ``verify`` without ``--result``
scores a model as it is.

Exit codes (calib.fit.verdict): 0 success (a residual above the tracker noise is said, not
refused); 2 bad input (the message names the cause); 3 the fit did not converge; 4 the data
do not fit the model (a likely data error named, too many outliers, implausible estimates
the data determine well, an implausible residual, or a residual above an explicit
``--max-ratio``; verify: readings that the result's registration leaves an order of magnitude
beyond its residual, likely another tracker station, without ``--register``); verify,
compensate and export of a result identify refused exit with identify's code (compensate and
export write nothing unless ``--force``); 5 some
desired poses out of reach (compensate); 6 a worker process was killed before it finished
(most often for lack of memory; nothing written); 130 interrupted.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
from pathlib import Path

import calib.cli.compensate as cmd_compensate
import calib.cli.export as cmd_export
import calib.cli.plan as cmd_plan
import calib.cli.verify_day as verify_day
import calib.cli.verify_iso as verify_iso
from calib.cli.common import (
    identify_exit_code,
    positive_int,
    print_verdict,
    prior_spec,
    ratio_float,
    run_fit,
    sigma_float,
)
from calib.cli.diagnose import cmd_diagnose
from calib.cli.verify_correction import with_correction
from calib.data import DatasetError, load_result, read_dataset, result_text, sidecar_path
from calib.exceptions import CalibError
from calib.fit import (
    DEFAULT_MAX_RATIO,
    DETERMINED_Z,
    EXIT_BAD_INPUT,
    EXIT_OK,
    EXIT_WORKER_LOST,
    CalibrationRun,
    model_from_files,
    probe_summary,
    regularisation_text,
    rejected_rows,
    result_content,
)
from calib.loop import model_for_result, parameter_entry, with_result_content
from common.atomic_files import json_text
from common.worker_processes import WorkerLost
from common.write_set import WriteSetError, write_files
from twin.exceptions import TwinError


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
    if run.fuller is not None:
        print(run.fuller.sentence())
    if run.obs.rotations is not None:
        print(probe_summary(run))
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
    for name, v, s, unit, est in zip(
        res.names, shown, std, params.display_units(), res.estimated, strict=True
    ):
        if est:
            tail = f"+- {s:.4f}" + ("  weakly identified" if name in weak else "")
        else:
            tail = f"(fixed at 0: {res.report.unidentifiable.get(name, 'not identifiable')})"
        print(f"  {name:32s} {v:+10.4f} {unit:3s} {tail}")
    if run.weak:
        print(
            f"{len(run.weak)} parameter(s) weakly identified (standard error above half the "
            f"physical range, value within {DETERMINED_Z:g} standard errors of zero); more "
            "poses over a larger volume determine them better"
        )
    print(regularisation_text(run))
    for group in run.groups[:5]:
        print(f"  near-collinear (|r| > 0.95): {', '.join(group)}")


def _say_directions(model, state) -> None:
    """Where the approach directions of a backlash came from (a column or the order)."""
    if model.offsets is not None and "direction" in model.offsets.needs and state is not None:
        print(f"approach directions: {state.source}")


def cmd_identify(args: argparse.Namespace) -> int:
    run = run_fit(args)
    if isinstance(run, int):
        return run
    _say_directions(run.model, run.obs.state)
    _print_run(run)
    print_verdict(run.verdict)
    if args.out:
        files = (args.model, args.errors, args.data)
        if args.with_effect:  # what --with added and held: what verify, compensate, export rebuild
            diagnosis = json.loads(Path(args.with_effect).read_text(encoding="utf-8"))
            base = model_from_files(args.model, args.errors)
            content = with_result_content(run, base, files, args.with_effect, diagnosis)
        else:
            content = result_content(run, *files)
            # a kept fuller model's parameters: what verify, compensate, export rebuild
            base = {p.name for p in model_from_files(args.model, args.errors).params.parameters}
            added = [parameter_entry(p) for p in run.model.params.parameters if p.name not in base]
            if added:
                content["added_parameters"] = added
        write_files({args.out: result_text(content)}, make_parents=True)
    return run.verdict.exit_code


def _csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def cmd_verify(args: argparse.Namespace) -> int:
    if args.result is None and (args.register or args.register_set or args.iso9283):
        raise CalibError(
            "--register, --register-set and --iso9283 score a result (--result R.json); a "
            "model scored as it is is registered on the 'calibration' rows, else on the "
            "scored ones"
        )
    if args.result is None:  # the model as it is, e.g. one written by export
        import calib.cli.verify_as_is as verify_as_is

        return verify_as_is.run(args)
    if args.errors is None:
        raise CalibError("verify --result needs --errors (the error model of the result)")
    model = model_from_files(args.model, args.errors)
    loaded = load_result(args.result, expected_model=model.nominal.name)
    model = model_for_result(model, loaded.data)
    dataset = read_dataset(args.data, expected_model=model.nominal.name)
    refused = identify_exit_code(loaded)
    if refused != EXIT_OK:
        message = (loaded.data.get("verdict") or {}).get("message", "")
        print(
            f"REFUSED RESULT: identify refused this result (exit {refused}): {message}; the "
            "scores below are of a fit the data did not support",
            file=sys.stderr,
        )
    chosen = verify_day.verification(model, loaded, dataset, args)
    if isinstance(chosen, int):
        return chosen
    v, selection = chosen
    print(selection)
    _say_directions(model, model.state)
    print(v.note)
    for side in ("before", "after"):
        print(getattr(v, side).line(f"{side:6s}"))
    corrected = with_correction(model, loaded, dataset, args.set, v.after.as_dict())
    if args.iso9283:  # the ISO report is what --out then writes
        content = {"result": str(args.result), "data": str(args.data), "set": args.set}
        values = loaded.values_for(model.params)
        verify_iso.run(model, values, dataset, v, args.out, {**content, "selection": selection})
        return refused
    if args.out:
        from calib.cli.verify_figure import save_verification_png

        out = Path(args.out)
        content = {"result": str(args.result), "data": str(args.data), "set": args.set}
        write_files(  # the three files together, or none of them
            {
                out: json_text(
                    {
                        **content,
                        **v.as_dict(),
                        "selection": selection,
                        **({"residual_correction": corrected} if corrected else {}),
                    }
                ),
                out.with_suffix(".csv"): _csv_text(v.rows()),
                out.with_suffix(".png"): lambda tmp: save_verification_png(v, tmp),
            },
            make_parents=True,
        )
        print(f"wrote {out}, {out.with_suffix('.csv')} and {out.with_suffix('.png')}")
    return refused


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
        "tracker accuracy explains (default: no such gate; a residual above the noise is "
        "reported, and is what `diagnose` is for)",
    )
    p.add_argument(
        "--max-iterations",
        type=positive_int,
        help="stop the fit after this many iterations (exit 3 if it has not converged by then)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pkm-calib",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True)
    ident = sub.add_parser("identify", help="identify geometric errors from a tracker dataset")
    _model_options(ident)
    _fit_options(ident)
    ident.add_argument(
        "--sigma-mm",
        type=sigma_float,
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
        "--plain",
        action="store_true",
        help="plain least squares over every identifiable parameter: keep no weakly "
        "determined direction at zero (the default does so where cross-validation over the "
        "poses says it predicts held-out readings no worse)",
    )
    ident.add_argument(
        "--with",
        dest="with_effect",
        metavar="D.json",
        help="add the effect a diagnosis named (diagnose --out D.json) to the error model as "
        "its static parameters (actuator gains, reflector offsets, joint-axis tilts) and fit "
        "geometry and effect together",
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
    verify_day.add_options(ver)
    diag = sub.add_parser(
        "diagnose", help="test the residual of a geometric calibration for unmodelled effects"
    )
    _model_options(diag)
    _fit_options(diag)
    diag.add_argument(
        "--sigma-mm",
        type=sigma_float,
        help="tracker noise per coordinate (mm); default: from the repeat readings, else the "
        "sidecar's tracker.sigma_mm; a typed value is checked against the repeats",
    )
    diag.add_argument(
        "--test",
        help="a Dataset CSV of poses not used to fit: an effect is named only if it lowers "
        "their error too (and not their largest); the JSON gets test.before and test.after. "
        "Its 'test' rows if it has any (or --test-set NAME), else its rows not fitted",
    )
    diag.add_argument(
        "--test-set",
        help="hold out the rows of this set (of --test FILE, or of --data) as the test set",
    )
    for command in (cmd_compensate, cmd_export, cmd_plan):  # each subcommand in its own module
        command.add_parser(sub)
    return parser


COMMANDS = {"identify": cmd_identify, "verify": cmd_verify, "diagnose": cmd_diagnose}
COMMANDS.update({"compensate": cmd_compensate.run, "export": cmd_export.run, "plan": cmd_plan.run})
# the files each command writes beside --out (same name, another suffix)
WRITTEN_BESIDE = {
    "identify": (),
    "verify": (".csv", ".png"),
    "diagnose": (".png",),
    "compensate": (".json",),
    "export": (),
    "plan": (".json", ".png"),
}


def check_out(args: argparse.Namespace) -> None:
    """Refuse, before any work, an ``--out`` whose files would overwrite an input or each
    other (``verify --out v.csv``) or that names a folder."""
    if not getattr(args, "out", None):
        return
    out = Path(args.out)
    outs = [out, *(out.with_suffix(s) for s in WRITTEN_BESIDE.get(args.command, ()))]
    if getattr(args, "dh_out", None):
        outs.append(Path(args.dh_out))
    if len(set(outs)) < len(outs):
        raise ValueError(
            f"--out {out}: a file written beside it would take its own name; give the main "
            "file its own suffix (verify and diagnose: .json, compensate: .csv)"
        )
    if out.is_dir():
        raise ValueError(f"--out {out} is a folder; name the file to write")
    roles = {
        "model": "the nominal model itself",
        "errors": "the error model",
        "data": "the dataset",
        "result": "the result file",
        "test": "the test dataset",
        "poses": "the desired poses",
        "commands": "the program",
    }
    inputs = {getattr(args, k, None): role for k, role in roles.items()}
    for path in [p for p in inputs if p and str(p).endswith(".csv")]:
        inputs[str(sidecar_path(path))] = f"the sidecar of {path}"
    for o in outs:
        for i, role in inputs.items():
            if i and o.exists() and Path(i).exists() and os.path.samefile(o, i):
                raise ValueError(f"--out {o} would overwrite an input file: {role} ({i})")


def os_error_text(exc: OSError, args: argparse.Namespace) -> str:
    """A file error as a sentence with its file: a WriteSetError's own sentence, else the
    OS's cause and file without the raw ``[Errno N]`` (no file known: the command's --out)."""
    if isinstance(exc, WriteSetError) or not exc.strerror:
        return str(exc)
    if exc.filename:
        return f"{exc.strerror}: {exc.filename}"
    out = getattr(args, "out", None)
    return f"{exc.strerror} (while writing {out})" if out else str(exc.strerror)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        check_out(args)
        return COMMANDS[args.command](args)
    except OSError as exc:
        print(f"error: {os_error_text(exc, args)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (DatasetError, CalibError, TwinError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except WorkerLost as exc:
        print(f"error: {exc}: nothing written", file=sys.stderr)
        return EXIT_WORKER_LOST
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
