"""Command line: ``python -m scenarios run NAME|PATH [--results DIR]`` and ``list``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from calib.exceptions import CalibError, DatasetError
from scenarios.config import SCENARIO_DIR, ScenarioError
from twin.exceptions import TwinError


def _shown(path: Path) -> str:
    """``results/<name>`` relative to the working directory when it lies below it."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m scenarios", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a scenario by name (scenarios/<name>.toml) or path")
    run.add_argument("scenario")
    run.add_argument("--results", type=Path, default=None, help="results root (default results/)")
    run.add_argument("--quiet", action="store_true")
    run.add_argument("--view", action="store_true", help="open the rerun viewer as well")
    run.add_argument("--no-record", action="store_true", help="do not write the .rrd file")
    sub.add_parser("list", help="list the scenarios shipped in scenarios/")
    args = parser.parse_args(argv)
    if args.command == "list":
        for f in sorted(SCENARIO_DIR.glob("*.toml")):
            print(f.stem)
        return 0
    try:
        from scenarios.runner import run_scenario

        summary, out_dir = run_scenario(
            args.scenario,
            args.results,
            quiet=args.quiet,
            view=args.view,
            record=not args.no_record,
        )
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (TwinError, CalibError, DatasetError) as exc:
        # a valid file asking for something the machine cannot do (a pose outside the
        # workspace, a rank-deficient plan): named, without a traceback; results untouched
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        where = getattr(exc, "out_dir", None)
        shown = f"{_shown(where)} left as it was" if where is not None else "nothing written"
        print(f"interrupted: {shown}", file=sys.stderr)
        return 130
    print(f"{out_dir / 'summary.json'} (runtime {summary.get('runtime_s', float('nan')):.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
