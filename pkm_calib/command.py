"""``pkm-calib``: one command for everything a user runs.

    pkm-calib identify|verify|diagnose|compensate|export|plan ...   (calib.cli)
    pkm-calib from-urdf|from-dh|error-model ...                      (twin.formats)
    pkm-calib scenario NAME|PATH|list ... , pkm-calib sweep ...      (the scenarios extra)

``python -m calib ...`` runs the same calibration commands. Each subcommand has its own
``--help``.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from collections.abc import Callable

from calib.cli import build_parser
from calib.cli import main as calib_main
from twin.formats import dh_table_command, error_model_command, from_urdf_command

PROG = "pkm-calib"
SCENARIOS_EXTRA = "pip install 'pkm-calib[scenarios]'"
# modules only the scenarios extra installs (rerun-sdk, Ray and what they pull in)
EXTRA_MODULES = frozenset({"rerun", "ray", "pyarrow"})

MODEL_COMMANDS: dict[str, tuple[Callable[[list[str]], int], str]] = {
    "from-urdf": (from_urdf_command, "turn a URDF into a nominal MJCF and its error model"),
    "from-dh": (dh_table_command, "turn a DH table (CSV) into a nominal MJCF and its error model"),
    "error-model": (error_model_command, "write the error model of any MJCF"),
}
SCENARIO_COMMANDS = {
    "scenario": "run a scenario (NAME, PATH, or 'list'); needs the scenarios extra",
    "sweep": "run a scenario over seeds and settings; needs the scenarios extra",
}


def missing_extra(command: str) -> str | None:
    """The first module of the scenarios extra that ``command`` needs and cannot import."""
    needs = ("rerun", "ray") if command == "sweep" else ("rerun",)
    for name in needs:
        try:
            if importlib.util.find_spec(name) is None:
                return name
        except (ImportError, ValueError):
            return name
    return None


def scenarios_main(command: str, rest: list[str]) -> int:
    """``scenarios``'s command line, imported only now: without the extra it says which one
    to install (exit 2) instead of a traceback."""
    missing = missing_extra(command)
    try:
        if missing is not None:
            raise ModuleNotFoundError(f"No module named {missing!r}", name=missing)
        from scenarios.__main__ import main as run_scenarios

        if command == "scenario":
            return run_scenarios(["list"] if rest == ["list"] else ["run", *rest], prog=PROG)
        return run_scenarios(["sweep", *rest], prog=PROG)
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0] not in EXTRA_MODULES:
            raise
        print(
            f"error: pkm-calib {command} needs the scenarios extra ({exc.name} is not "
            f"installed): {SCENARIOS_EXTRA}",
            file=sys.stderr,
        )
        return 2


def full_parser() -> argparse.ArgumentParser:
    """calib's parser with the model and scenario commands listed (each parses its own
    arguments: ``pkm-calib from-urdf --help``)."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, (_, text) in MODEL_COMMANDS.items():
        sub.add_parser(name, help=text, add_help=False)
    for name, text in SCENARIO_COMMANDS.items():
        sub.add_parser(name, help=text, add_help=False)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one ``pkm-calib`` subcommand; returns its exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] in MODEL_COMMANDS:
        return MODEL_COMMANDS[args[0]][0](args[1:])
    if args and args[0] in SCENARIO_COMMANDS:
        return scenarios_main(args[0], args[1:])
    if not args or args[0] in ("-h", "--help"):
        full_parser().parse_args(args)  # prints the usage (exit 0 for --help, 2 without)
    return calib_main(args)


if __name__ == "__main__":
    sys.exit(main())
