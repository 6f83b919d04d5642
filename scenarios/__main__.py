"""Command line: ``python -m scenarios run NAME|PATH [--results DIR] [--no-record]
[--no-figures]``, ``list``, and
``sweep NAME|PATH --seeds N [--over truth|noise|both] [--set key=v1,v2 ...] [--engine ray|local]``
(Ray: a local instance, or the cluster RAY_ADDRESS names)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from calib.exceptions import CalibError, DatasetError
from scenarios.config import ScenarioError, scenario_files
from twin.exceptions import TwinError


def _shown(path: Path) -> str:
    """``results/<name>`` relative to the working directory when it lies below it."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _os_message(exc: OSError) -> str:
    """What a file error says: ResultsWriteError's sentence, else its cause and file."""
    from common.write_set import WriteSetError
    from scenarios.results_folder import ResultsWriteError, describe_os_error

    if isinstance(exc, (ResultsWriteError, WriteSetError)):
        return str(exc.strerror)
    return describe_os_error(exc)


def main(argv: list[str] | None = None, prog: str = "python -m scenarios") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser(
        "run", help="run a scenario by name (scenarios/studies/<study>/<name>.toml) or path"
    )
    run.add_argument("scenario")
    run.add_argument("--results", type=Path, default=None, help="results root (default results/)")
    run.add_argument("--quiet", action="store_true")
    run.add_argument("--view", action="store_true", help="open the rerun viewer as well")
    run.add_argument("--no-record", action="store_true", help="do not write the .rrd file")
    run.add_argument(
        "--no-figures",
        action="store_true",
        help="leave out the PNG figures (studies that support it; the numbers are the same)",
    )
    sub.add_parser("list", help="list the scenarios shipped in scenarios/")
    sw = sub.add_parser(
        "sweep",
        help="run a scenario's study once per seed (and per swept setting) as Ray tasks",
    )
    sw.add_argument("scenario")
    sw.add_argument("--seeds", type=int, required=True, help="runs per setting")
    sw.add_argument("--over", choices=("truth", "noise", "both"), default="both")
    sw.add_argument(
        "--set",
        dest="sets",
        action="append",
        default=[],
        metavar="KEY=V1[,V2 ...]",
        help="override a scenario key; several values sweep it (repeatable)",
    )
    sw.add_argument(
        "--engine",
        choices=("ray", "local"),
        default="ray",
        help="ray (default: local instance, or the cluster RAY_ADDRESS names) or in-process",
    )
    sw.add_argument("--results", type=Path, default=None, help="results root (default results/)")
    sw.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    if args.command == "list":
        for f in scenario_files():
            print(f.stem)
        return 0
    if args.command == "sweep":
        return _sweep(args)
    try:
        from scenarios.runner import run_scenario

        summary, out_dir = run_scenario(
            args.scenario,
            args.results,
            quiet=args.quiet,
            view=args.view,
            record=not args.no_record,
            figures=not args.no_figures,
        )
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (TwinError, CalibError, DatasetError) as exc:
        # a valid file asking for something the machine cannot do (a pose outside the
        # workspace, a rank-deficient plan): named, without a traceback; results untouched
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a full disk, a read-only or immutable results folder
        print(f"error: {_os_message(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        where = getattr(exc, "out_dir", None)
        shown = f"{_shown(where)} left as it was" if where is not None else "nothing written"
        print(f"interrupted: {shown}", file=sys.stderr)
        return 130
    print(f"{out_dir / 'summary.json'} (runtime {summary.get('runtime_s', float('nan')):.1f} s)")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from scenarios.sweep.engine import EngineError
    from scenarios.sweep.runner import sweep

    try:
        summary, out_dir = sweep(
            args.scenario,
            args.seeds,
            over=args.over,
            sets=args.sets,
            engine=args.engine,
            results_root=args.results,
            quiet=args.quiet,
        )
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except EngineError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a full disk, a read-only or immutable results folder
        print(f"error: {_os_message(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: finished runs kept; run again to resume", file=sys.stderr)
        return 130
    print(
        f"{_shown(out_dir / 'summary.json')} ({summary['n_runs']} runs, "
        f"{summary['n_failed']} failed, engine {summary['engine']})"
    )
    return 1 if summary["n_failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
