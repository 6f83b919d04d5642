"""``pkm-calib export``: the calibrated model, for the controller or a simulator.

    pkm-calib export --model M.xml --errors E.toml --result R.json
                           --out M_calibrated.xml [--dh-out T.csv]

Writes the nominal MJCF with the identified errors in its geometry (body positions and
orientations, joint zeros as ``ref``, reflector sites; every other line as it was) and the
actuator gains as the actuators' ``gear`` (a command c sets the joint to
zero + (c - zero)(1 + gain)), after checking that its forward kinematics equals the identified
model's to 1e-9 m at commands spread over the workspace. What an MJCF cannot hold (joint
compliances) is listed beside it in M_calibrated.xml.calibration.json, which ``verify --model``
names in its first line. With ``--dh-out``, for a model generated from a DH table
(pkm-calib from-dh), the calibrated DH table. ``verify --model M_calibrated.xml``
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
    p.add_argument(
        "--urdf-out",
        help="also write the calibrated URDF of a model generated from one (from_urdf)",
    )
    p.add_argument(
        "--urdf",
        help="the URDF the model was generated from (default: the one its header names, beside it)",
    )


def run(args: argparse.Namespace) -> int:
    model = model_from_files(args.model, args.errors)
    machine = load_identified_machine(model, args.result)
    refused = refused_result(machine.result, args.force, "export")
    if refused:  # identify's own exit code and reason
        return refused
    done = export_model(
        machine, args.model, args.out, args.dh_out, urdf_out=args.urdf_out, urdf=args.urdf
    )
    w, c = done.written, done.check
    print(
        f"wrote {done.out}: {len(w.bodies)} bodies placed anew, {len(w.sites)} sites moved, "
        f"{len(w.joints)} joint zeros shifted, {len(w.actuators)} actuator gains as gears "
        f"(the rest of {args.model} as it was)"
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
        print(f"the {gains}")
    if done.not_held:
        names = ", ".join(m["name"] for m in done.not_held)
        print(
            f"wrote {done.sidecar}: {len(done.not_held)} identified parameter(s) the MJCF "
            f"cannot hold ({names}); the check above is without them, and verify --model "
            f"{done.out} says so first"
        )
    else:
        print(f"wrote {done.sidecar}: the model holds every identified parameter")
    if done.dh_out is not None:
        print(f"wrote {done.dh_out}: the calibrated DH table")
    if done.urdf is not None:
        u = done.urdf
        print(
            f"wrote {done.urdf_out}: the calibrated URDF (joint origins; its forward kinematics "
            f"read back against the identified model's: max {u.calibrated_m * 1e3:.3g} mm; the "
            f"URDF given against the nominal model: {u.nominal_m * 1e3:.3g} mm) and {u.sidecar}: "
            + (
                f"{len(u.not_held)} identified parameter(s) a URDF cannot hold ("
                + ", ".join(m["name"] for m in u.not_held)
                + ")"
                if u.not_held
                else "it holds every identified parameter"
            )
        )
    return EXIT_OK
