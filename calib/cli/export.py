"""``python -m calib export``: the calibrated model, for the controller or a simulator.

    python -m calib export --model M.xml --errors E.toml --result R.json
                           --out M_calibrated.xml [--dh-out T.csv]

Writes the nominal MJCF with the identified errors in its geometry (body positions and
orientations, joint zeros as ``ref``, reflector sites; every other line as it was), after
checking that its forward kinematics equals the identified model's to 1e-9 m at commands
spread over the workspace; with ``--dh-out``, for a model generated from a DH table
(python -m twin.formats.dh_table), the calibrated DH table. ``verify --model M_calibrated.xml``
without ``--result`` then scores it as it is on new readings. Exit 0, or 2 with the cause
and nothing written.
"""

from __future__ import annotations

import argparse

from calib.cli.common import refused_result, result_options
from calib.compensate import FK_TOLERANCE_M, export_model, gains_text, load_identified_machine
from calib.fit import EXIT_OK, model_from_files


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="write the calibrated MJCF (and DH table) with the identified errors in it",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    result_options(p)
    p.add_argument("--out", required=True, help="the calibrated MJCF to write")
    p.add_argument(
        "--dh-out",
        help="also write the calibrated DH table (CSV) of a model generated from one",
    )


def run(args: argparse.Namespace) -> int:
    model = model_from_files(args.model, args.errors)
    machine = load_identified_machine(model, args.result)
    refused = refused_result(machine.result, args.force, "export")
    if refused:  # identify's own exit code and reason
        return refused
    done = export_model(machine, args.model, args.out, args.dh_out)
    w, c = done.written, done.check
    print(
        f"wrote {done.out}: {len(w.bodies)} bodies placed anew, {len(w.sites)} sites moved, "
        f"{len(w.joints)} joint zeros shifted (the rest of {args.model} as it was)"
    )
    print(
        f"forward kinematics of the written model against the identified one at "
        f"{c.n_commands} commands: max {c.max_position_m * 1e3:.3g} mm (targets and tool "
        f"point), tool frame {c.max_rotation_rad:.3g} rad (limit {FK_TOLERANCE_M * 1e3:g} mm)"
    )
    if machine.registration is not None:
        print(
            "the tracker registration is not part of the model: readings in the tracker's "
            "frame are registered again when the model is verified"
        )
    gains = gains_text(machine)
    if gains:
        print(f"the {gains}; the check above is in joint values")
    if done.dh_out is not None:
        print(f"wrote {done.dh_out}: the calibrated DH table")
    return EXIT_OK
