"""``python -m calib compensate``: the commands that put the identified machine where asked.

    python -m calib compensate --model M.xml --errors E.toml --result R.json
                               --poses desired.csv --out commands.csv [--frame base|tracker]
                               [--diagnosis D.json]

Reads desired tool poses (calib.data.desired_poses: ``pose_id,x_mm,y_mm,z_mm[,rx_deg,ry_deg,
rz_deg]``), in the machine's base frame or, with ``--frame tracker``, in the tracker's frame
through the registration identified with the result; rows without an orientation keep the
nominal one (the tool's at the nominal home). Writes ``commands.csv`` (``pose_id``, one
``cmd:<actuator>`` column per actuator in mm or deg, the residual the identified model
predicts at those commands, and the error it predicts for the nominal commands) and a
sidecar ``commands.json`` (units, frame, the poses not reachable and why). A pose out of
reach or past a stroke is named with the actuator and by how much; the others are written.
Exit 0 when every pose was reachable, 5 when some were not, 2 on bad input (nothing written).

With ``--diagnosis D.json`` the machine compensated is the identified one with the effect the
diagnosis named: the result must be the one ``identify --with D.json`` wrote (geometry and
effect fitted together, the effect's parameters among the result's); a result fitted without
it is refused with that advice rather than combined with the diagnosis's own estimate.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from pathlib import Path

import numpy as np

from calib.cli.common import result_options
from calib.compensate import Compensation, IdentifiedMachine, compensate, load_identified_machine
from calib.data import DesiredPoses, DesiredPosesError, read_desired_poses
from calib.fit import EXIT_OK, EXIT_UNREACHABLE, model_from_files
from calib.loop import EffectFileError, load_effect
from common.atomic_files import json_text
from common.write_set import write_files
from twin.kinematics import forward
from twin.rotations import matrix_from_rpy, rpy_from_matrix

FRAMES = ("base", "tracker")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compensate",
        help="actuator commands that put the identified machine at desired tool poses",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    result_options(p)
    p.add_argument(
        "--poses", required=True, help="desired tool poses: pose_id,x_mm,y_mm,z_mm[,rx_deg,...]"
    )
    p.add_argument("--out", required=True, help="the commands CSV to write (and its .json)")
    p.add_argument(
        "--diagnosis",
        metavar="D.json",
        help="the diagnosis whose named effect the result carries (identify --with D.json): "
        "checked, and the machine compensated with it",
    )
    p.add_argument(
        "--frame",
        choices=FRAMES,
        default="base",
        help="frame of the desired poses: the machine's base (default) or the tracker's, "
        "through the registration identified with the result",
    )


def nominal_orientation(machine: IdentifiedMachine) -> np.ndarray:
    """The tool's rotation (3, 3) on the nominal model at its home configuration."""
    nominal = machine.nominal
    return forward(nominal, nominal.home_qpos[nominal.actuator_qpos]).tool_rotation


def poses_in_base(desired: DesiredPoses, frame: str, machine: IdentifiedMachine) -> np.ndarray:
    """Desired poses (N, 6) in the base frame (SI, rpy); position-only rows take the
    nominal orientation."""
    pos = np.array(desired.positions)
    given = desired.has_orientation
    rot = np.empty((len(desired), 3, 3))
    rot[given] = matrix_from_rpy(desired.rpy[given])
    if frame == "tracker":
        reg = machine.registration
        if reg is None:
            raise DesiredPosesError(
                f"--frame tracker: the result {machine.result.path} was identified from "
                "base-frame readings and has no tracker registration to carry the poses with"
            )
        pos = reg.to_base(pos)
        rot[given] = reg.rotation @ rot[given]
    rot[~given] = nominal_orientation(machine)
    rpy = rpy_from_matrix(rot)
    off = np.max(np.abs(matrix_from_rpy(rpy) - rot), axis=(1, 2))
    for i in np.flatnonzero(off > 1e-9):
        raise DesiredPosesError(
            f"pose_id '{desired.pose_ids[i]}': its orientation in the base frame has ry at "
            "+-90 deg, where rx and rz are one angle: turn the request slightly"
        )
    return np.hstack([pos, rpy])


def _fmt(value: float) -> str:
    return "" if not np.isfinite(value) else repr(float(value))


def commands_csv(machine: IdentifiedMachine, comp: Compensation) -> str:
    """The rows of the reachable poses: pose_id, cmd:<actuator> (mm, deg), residuals."""
    mech = machine.nominal
    names = [f"cmd:{a}" for a in mech.actuator_names]
    tail = ["predicted_residual_mm", "predicted_residual_deg", "predicted_error_nominal_mm"]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["pose_id", *names, *tail])
    scale = np.where(mech.actuator_is_slide, 1e3, np.degrees(1.0))
    for i in np.flatnonzero(comp.reachable):
        writer.writerow(
            [
                comp.pose_ids[i],
                *(_fmt(v) for v in comp.commands[i] * scale),
                _fmt(comp.residual_m[i] * 1e3),
                _fmt(np.degrees(comp.residual_rad[i])),
                _fmt(comp.nominal_error_m[i] * 1e3),
            ]
        )
    return buf.getvalue()


def sidecar(args: argparse.Namespace, machine: IdentifiedMachine, comp: Compensation) -> dict:
    mech = machine.nominal
    ok = comp.reachable
    return {
        "format": "pkm-calib-commands",
        "version": 1,
        "model": mech.name,
        "result": str(args.result),
        "poses": str(args.poses),
        "frame": args.frame,
        "units": {
            f"cmd:{a}": "mm" if s else "deg"
            for a, s in zip(mech.actuator_names, mech.actuator_is_slide, strict=True)
        },
        "nominal_orientation_rpy_deg": np.degrees(
            rpy_from_matrix(nominal_orientation(machine))
        ).tolist(),
        "n_poses": len(comp.pose_ids),
        "n_written": int(ok.sum()),
        "unreachable": [
            {"pose_id": comp.pose_ids[i], "reason": comp.problems[i]} for i in np.flatnonzero(~ok)
        ],
        "columns": {
            "predicted_residual_mm": "3D distance between the desired tool point and the one "
            "the identified model predicts at the written commands",
            "predicted_residual_deg": "angle between the desired tool frame and the predicted one",
            "predicted_error_nominal_mm": "3D error the identified model predicts for the "
            "nominal model's commands of the same pose (what compensation corrects)",
        },
    }


def with_diagnosis(model, machine: IdentifiedMachine, path: str) -> str:
    """Check that the result carries the effect the diagnosis ``path`` named; a sentence."""
    block = load_effect(path, model)
    carried = {p["name"] for p in machine.result.data.get("added_parameters") or []}
    wanted = [p["name"] for p in block["added_parameters"]]
    missing = [n for n in wanted if n not in carried]
    if missing:
        raise EffectFileError(
            f"the result {machine.result.path} was fitted without the effect {path} names "
            f"({block['named']}: {', '.join(missing[:4])} missing): run `calib identify ... "
            f"--with {path} --out R.json` and compensate that result, where geometry and "
            "effect are fitted together"
        )
    return f"with {block['named']} ({len(wanted)} parameters fitted with the geometry)"


def run(args: argparse.Namespace) -> int:
    model = model_from_files(args.model, args.errors)
    machine = load_identified_machine(model, args.result)
    if args.diagnosis:
        print(with_diagnosis(model, machine, args.diagnosis))
    desired = read_desired_poses(args.poses)
    poses = poses_in_base(desired, args.frame, machine)
    comp = compensate(machine, poses, desired.pose_ids)
    out = Path(args.out)
    text = commands_csv(machine, comp)
    side = json_text(sidecar(args, machine, comp))
    write_files({out: text, out.with_suffix(".json"): side}, make_parents=True)  # both, or neither
    ok = comp.reachable
    where = "base frame" if args.frame == "base" else "tracker frame, identified registration"
    print(f"compensated {int(ok.sum())} of {len(ok)} poses ({where})")
    if ok.any():
        r, e = comp.residual_m[ok] * 1e3, comp.nominal_error_m[ok] * 1e3
        e = e[np.isfinite(e)]
        line = f"predicted residual at the written commands: max {np.max(r):.3g} mm"
        if e.size:
            line += (
                f"; the nominal commands would leave {np.sqrt(np.mean(e * e)):.4f} mm RMS "
                f"(max {np.max(e):.4f} mm) by the identified model"
            )
        print(line)
    for i in np.flatnonzero(~ok):
        print(f"pose_id {comp.pose_ids[i]}: {comp.problems[i]}", file=sys.stderr)
    print(f"wrote {out} and {out.with_suffix('.json')}")
    return EXIT_OK if ok.all() else EXIT_UNREACHABLE
