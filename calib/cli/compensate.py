"""``pkm-calib compensate``: the commands that put the identified machine where asked.

    pkm-calib compensate --model M.xml --errors E.toml --result R.json
                               --commands program.csv --out corrected.csv
    pkm-calib compensate --model M.xml --errors E.toml --result R.json --poses desired.csv
        [--commands program.csv | --seed A1=0,...] --out commands.csv [--frame base|tracker]
        [--diagnosis D.json] [--force]

``--commands``: a robot's program (calib.data.program: ``pose_id`` and the Dataset's
``cmd:<actuator>`` columns in mm or deg; a Dataset CSV is one too, other columns ignored).
Each target becomes the commands that put the identified machine's tool frame, position and
orientation, where the nominal model puts it at the program's commands, solved from the
program's own configuration (the same branch; calib.compensate.program).

``--poses``: desired tool poses (calib.data.desired_poses: ``pose_id,x_mm,y_mm,z_mm[,rx_deg,
ry_deg,rz_deg]``), in the machine's base frame or, with ``--frame tracker``, in the tracker's
frame through the registration identified with the result. Each pose is solved from a seed's
configuration, and a row without an orientation takes the seed's tool orientation: the
nearest target of ``--commands`` (by the nominal tool point), or the one ``--seed`` (every
actuator, ``A1=0,A2=-90,...`` by name or ``0,-90,...`` in the model's order, mm or deg);
without either, from home with the tool's orientation at the nominal home.

Writes the commands CSV (``pose_id``, one ``cmd:<actuator>`` column per actuator in mm or
deg, the residual the identified model predicts at those commands, the error it predicts for
the nominal or program commands, and with a seed the seed of each pose) and a sidecar
``.json`` (units, inputs, the seed, the poses not reachable and why). A pose out of reach or
past a stroke is named with the actuator and by how much; the others are written. Exit 0
when every pose was reachable, 5 when some were not, 2 on bad input (nothing written); a
result identify refused: identify's exit code and reason, nothing written, unless ``--force``.

A result whose error model reads the state at each target (a backlash: the approach
direction; a thermal growth or drift: the time; a thermal expansion: the temperature) is
compensated at the state the program will run at: the program's ``dir:<actuator>``,
``order``, ``time_s``, ``temperature_c`` columns, else ``--time-s`` / ``--temperature-c`` for
every target, the directions else from the program's own sequence (calib.compensate.run_state);
which it used is said, a missing one refused by name.

With ``--diagnosis D.json`` the machine compensated is the identified one with the effect the
diagnosis named: the result must be the one ``identify --with D.json`` wrote (others refused).
A result's residual correction is applied inside its calibrated region (the others listed).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from calib.cli.common import identify_exit_code, refused_result, result_options
from calib.cli.compensate_files import commands_csv, program_changes, sidecar
from calib.compensate import (
    Compensation,
    IdentifiedMachine,
    NominalTargets,
    compensate,
    compensate_program,
    load_identified_machine,
    nearest_targets,
    nominal_commands_error,
    nominal_targets,
    run_state,
    shown_residual,
    solve_each,
    with_residual_correction,
)
from calib.data import (
    DesiredPoses,
    DesiredPosesError,
    ProgramError,
    parse_seed,
    read_desired_poses,
    read_program,
)
from calib.fit import (
    EXIT_OK,
    EXIT_UNREACHABLE,
    Registration,
    model_from_files,
    nominal_registration,
)
from calib.loop import EffectFileError, load_effect
from common.atomic_files import json_text
from common.write_set import write_files
from twin.kinematics import forward
from twin.rotations import matrix_from_rpy, rpy_from_matrix

FRAMES = ("base", "tracker")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compensate",
        help="corrected commands: a robot's program, or desired tool poses, on the identified "
        "machine",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    result_options(p)
    p.add_argument(
        "--commands",
        metavar="program.csv",
        help="the robot's program: pose_id,cmd:<actuator>,... (mm, deg; a Dataset CSV too); "
        "alone: corrected; with --poses: the seeds of the poses",
    )
    p.add_argument("--poses", help="desired tool poses: pose_id,x_mm,y_mm,z_mm[,rx_deg,...]")
    p.add_argument(
        "--seed",
        metavar="A1=0,A2=-90,...",
        help="with --poses: the commands (mm, deg) whose configuration and tool orientation "
        "seed every pose (all actuators, by name or in the model's order)",
    )
    p.add_argument("--out", required=True, help="the commands CSV to write (and its .json)")
    p.add_argument(
        "--diagnosis",
        metavar="D.json",
        help="the diagnosis whose named effect the result carries (identify --with D.json): "
        "checked, and the machine compensated with it",
    )
    p.add_argument(
        "--time-s",
        type=float,
        default=None,
        help="the time since warm-up (s) at which the program will run, for a result's "
        "thermal growth or drift (or a time_s column of the program)",
    )
    p.add_argument(
        "--temperature-c",
        type=float,
        default=None,
        help="the temperature (deg C) at which the program will run, for a result's thermal "
        "expansion (or a temperature_c column of the program)",
    )
    p.add_argument(
        "--frame",
        choices=FRAMES,
        default=None,
        help="frame of the desired poses: the machine's base (default) or the tracker's, "
        "through the registration identified with the result",
    )


def check_inputs(args: argparse.Namespace) -> None:
    """Refuse, before any work, options that do not go together."""
    if not args.commands and not args.poses:
        raise ValueError(
            "compensate needs --commands program.csv (the robot's joint targets) or --poses "
            "desired.csv (tool poses)"
        )
    if args.seed and not args.poses:
        raise ValueError("--seed seeds desired poses: give --poses with it")
    if args.seed and args.commands:
        raise ValueError(
            "--seed and --commands both seed the poses: give one (--commands: the nearest "
            "program target of each pose; --seed: one configuration for all)"
        )
    if args.frame and not args.poses:
        raise ValueError("--frame is the frame of --poses; a program's commands have none")


def nominal_orientation(machine: IdentifiedMachine) -> np.ndarray:
    """The tool's rotation (3, 3) on the nominal model at its home configuration."""
    nominal = machine.nominal
    return forward(nominal, nominal.home_qpos[nominal.actuator_qpos]).tool_rotation


def positions_in_base(
    desired: DesiredPoses,
    frame: str,
    machine: IdentifiedMachine,
    registration: Registration | None = None,
) -> np.ndarray:
    """Desired tool points (N, 3) in the base frame (SI); tracker-frame ones through
    ``registration`` (default: the identified one)."""
    pos = np.array(desired.positions)
    if frame != "tracker":
        return pos
    if registration is not None:
        return registration.to_base(pos)
    if machine.registration is None:
        raise DesiredPosesError(
            f"--frame tracker: the result {machine.result.path} was identified from "
            "base-frame readings and has no tracker registration to carry the poses with"
        )
    return machine.registration.to_base(pos)


def poses_in_base(
    desired: DesiredPoses,
    frame: str,
    machine: IdentifiedMachine,
    seed_rotations: np.ndarray | None = None,
    registration: Registration | None = None,
) -> np.ndarray:
    """Desired poses (N, 6) in the base frame (SI, rpy); position-only rows take the seed's
    tool orientation ``seed_rotations`` (N, 3, 3) (base frame), else the nominal home's;
    tracker-frame ones through ``registration`` (default: the identified one)."""
    pos = positions_in_base(desired, frame, machine, registration)
    given = desired.has_orientation
    rot = np.empty((len(desired), 3, 3))
    rot[given] = matrix_from_rpy(desired.rpy[given])
    if frame == "tracker":
        rot[given] = (registration or machine.registration).rotation @ rot[given]
    rot[~given] = nominal_orientation(machine) if seed_rotations is None else seed_rotations[~given]
    rpy = rpy_from_matrix(rot)
    off = np.max(np.abs(matrix_from_rpy(rpy) - rot), axis=(1, 2))
    for i in np.flatnonzero(off > 1e-9):
        raise DesiredPosesError(
            f"pose_id '{desired.pose_ids[i]}': its orientation in the base frame has ry at "
            "+-90 deg, where rx and rz are one angle: turn the request slightly"
        )
    return np.hstack([pos, rpy])


def with_diagnosis(model, machine: IdentifiedMachine, path: str) -> str:
    """Check that the result carries the effect the diagnosis ``path`` named; a sentence."""
    block = load_effect(path, model)
    carried = {p["name"] for p in machine.result.data.get("added_parameters") or []}
    wanted = [p["name"] for p in block["added_parameters"]]
    missing = [n for n in wanted if n not in carried]
    if missing:
        raise EffectFileError(
            f"the result {machine.result.path} was fitted without the effect {path} names "
            f"({block['named']}: {', '.join(missing[:4])} missing): run `pkm-calib identify ... "
            f"--with {path} --out R.json` and compensate that result, where geometry and "
            "effect are fitted together"
        )
    return f"with {block['named']} ({len(wanted)} parameters fitted with the geometry)"


@dataclass(frozen=True)
class Seeds:
    """Where each desired pose starts: a configuration and a tool orientation (or home)."""

    starts: np.ndarray | None  # (N, nq) nominal configurations
    rotations: np.ndarray | None  # (N, 3, 3) base frame, for position-only rows
    labels: list[str] | None  # the seed of each pose, for the CSV
    record: dict[str, Any]  # for the sidecar
    sentence: str


def _seed_sentence(source: str, desired: DesiredPoses) -> str:
    k = int((~desired.has_orientation).sum())
    return (
        f"seed: {source}: the configuration (branch) of all {len(desired)} poses and the tool "
        f"orientation of the {k} without one"
    )


def seeds_for(args: argparse.Namespace, machine: IdentifiedMachine, desired: DesiredPoses) -> Seeds:
    """The seeds of the desired poses: the nearest program target, the one --seed, or home."""
    mech = machine.nominal
    n = len(desired)
    if args.commands:
        program = read_program(args.commands, mech.actuator_names, mech.actuator_is_slide)
        targets = nominal_targets(mech, program.commands)
        pos = positions_in_base(desired, args.frame or "base", machine)
        idx = nearest_targets(targets, pos)
        if np.any(idx < 0):
            raise ProgramError(
                f"{args.commands}: no target is usable as a seed (first: pose_id "
                f"{program.pose_ids[0]}: {targets.problems[0]})"
            )
        far = float(np.max(np.linalg.norm(pos - targets.positions[idx], axis=1))) * 1e3
        labels = [program.pose_ids[j] for j in idx]
        return Seeds(
            targets.qpos[idx],
            targets.rotations[idx],
            labels,
            {
                "source": "program",
                "commands": str(args.commands),
                "rule": "the program target whose nominal tool point is nearest",
                "max_distance_mm": far,
                "per_pose": dict(zip(desired.pose_ids, labels, strict=True)),
            },
            _seed_sentence(
                f"the nearest target of {args.commands} (nominal tool point at most {far:.1f} "
                "mm away)",
                desired,
            ),
        )
    if args.seed:
        c = parse_seed(args.seed, mech.actuator_names, mech.actuator_is_slide)
        one: NominalTargets = nominal_targets(mech, c[None])
        if one.problems[0] is not None:
            raise ProgramError(f"--seed {args.seed}: {one.problems[0]}")
        shown = c * np.where(mech.actuator_is_slide, 1e3, np.degrees(1.0))
        return Seeds(
            np.repeat(one.qpos, n, axis=0),
            np.repeat(one.rotations, n, axis=0),
            ["--seed"] * n,
            {
                "source": "--seed",
                "commands": {a: float(v) for a, v in zip(mech.actuator_names, shown, strict=True)},
            },
            _seed_sentence(f"--seed {args.seed}", desired),
        )
    k = int((~desired.has_orientation).sum())
    sentence = "no seed (--commands or --seed): every pose solved from home" + (
        f"; {k} position-only pose(s) keep the tool orientation at the nominal home" if k else ""
    )
    return Seeds(None, None, None, {"source": "home"}, sentence)


def honest_before(
    machine: IdentifiedMachine,
    comp: Compensation,
    reg0: Registration | None,
    nominal_commands: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[Compensation, str]:
    """``comp`` with the nominal commands' error in the frame every command shares (``reg0``:
    calib.fit.nominal_registration; calib.compensate.before), and that frame in words.
    ``nominal_commands``: (commands, nominal configurations) when not ``comp``'s own."""
    cmds, qpos = nominal_commands or (comp.nominal_commands, comp.nominal_qpos)
    error, reflectors = nominal_commands_error(machine, cmds, qpos, reg0)
    if machine.registration is None:
        where = "base frame"
    elif reg0 is None:
        where = (
            "not available: the result's calibration set, which defines the nominal model's "
            "registration, is not readable"
        )
    else:
        where = "tracker frame, the nominal model registered on the calibration set"
    return replace(comp, nominal_error_m=error, nominal_reflector_error_m=reflectors), where


def _residual_line(comp: Compensation, own: str, where: str = "") -> str | None:
    ok = comp.reachable
    if not ok.any():
        return None
    r, t = comp.residual_m[ok] * 1e3, np.degrees(comp.residual_rad[ok])
    e = comp.nominal_error_m[ok] * 1e3
    e = e[np.isfinite(e)]
    line = "predicted residual at the written commands: max " + ", ".join(
        (shown_residual(float(np.max(r)), "mm"), shown_residual(float(np.max(t)), "deg"))
    )
    if e.size:
        line += (
            f"; {own} would leave {np.sqrt(np.mean(e * e)):.4f} mm RMS (max {np.max(e):.4f} mm) "
            f"at the tool point by the identified model ({where})"
        )
        refl = comp.nominal_reflector_error_m
        if refl is not None:
            f = refl[ok][np.isfinite(refl[ok])] * 1e3
            line += (
                f", {np.sqrt(np.mean(f * f)):.4f} mm RMS at the reflectors (what the tracker "
                "measures; the tool point is extrapolated from them)"
            )
    elif where.startswith("not available"):
        line += f"; what {own} would leave: {where}"
    return line


def run(args: argparse.Namespace) -> int:
    check_inputs(args)
    model = model_from_files(args.model, args.errors)
    machine = load_identified_machine(model, args.result)
    refused = refused_result(machine.result, args.force, "compensate")
    if refused:  # identify's own exit code and reason, nothing written
        return refused
    if args.diagnosis:
        print(with_diagnosis(model, machine, args.diagnosis))
    mech = machine.nominal
    inputs: dict[str, Any] = {
        "result": str(args.result),
        "identify_exit_code": identify_exit_code(machine.result),
        "forced": bool(args.force and identify_exit_code(machine.result) != EXIT_OK),
    }
    labels = None
    where = ""
    program = None
    if not args.poses:
        program = read_program(args.commands, mech.actuator_names, mech.actuator_is_slide)
    n = len(program) if program is not None else len(read_desired_poses(args.poses))
    state, said = run_state(machine.model, program, n, args.time_s, args.temperature_c)
    machine.model.bind_state(state)  # the targets' state, for the kinds that read it
    for line in said:
        print(line)
    if said:
        inputs["state"] = said
    if args.poses:
        desired = read_desired_poses(args.poses)
        frame = args.frame or "base"
        seeds = seeds_for(args, machine, desired)
        poses = poses_in_base(desired, frame, machine, seeds.rotations)
        comp = compensate(machine, poses, desired.pose_ids, seeds.starts)
        before_commands = None
        reg0 = nominal_registration(model, machine.result)
        if frame == "tracker" and reg0 is not None:  # the nominal controller's own aim
            aimed = poses_in_base(desired, frame, machine, seeds.rotations, reg0)
            solved = solve_each(mech, aimed, seeds.starts)
            before_commands = (solved.commands, solved.qpos)
        comp, where = honest_before(machine, comp, reg0, before_commands)
        labels = seeds.labels
        inputs.update(
            poses=str(args.poses),
            frame=frame,
            nominal_orientation_rpy_deg=np.degrees(
                rpy_from_matrix(nominal_orientation(machine))
            ).tolist(),
            seed=seeds.record,
        )
        where = "base frame" if frame == "base" else "tracker frame, identified registration"
        head = f"compensated {int(comp.reachable.sum())} of {len(desired)} poses ({where})"
        lines = [seeds.sentence, _residual_line(comp, "the nominal commands", where)]
    else:
        assert program is not None
        reg0 = nominal_registration(model, machine.result)
        comp = compensate_program(machine, program.commands, program.pose_ids, reg0)
        comp, where = honest_before(machine, comp, reg0)
        changes = program_changes(machine, comp)
        inputs.update(
            commands=str(args.commands),
            target="the tool frame (position and orientation) of the nominal model at each "
            "target's commands, solved from the program's configuration",
            changes_from_program=changes,
        )
        head = (
            f"compensated {int(comp.reachable.sum())} of {len(program)} program targets (the "
            "identified tool frame where the nominal model puts it at each target's commands, "
            "solved from the program's configuration)"
        )
        moved = ", ".join(
            f"{a} {c['max']:.4g} {c['unit']} (pose_id {c['pose_id']})" for a, c in changes.items()
        )
        lines = [
            _residual_line(comp, "the program's own commands", where),
            f"largest change from the program: {moved}" if moved else None,
        ]
    comp, said, corrected = with_residual_correction(machine, comp)  # the result's, if any
    inputs.update({"residual_correction": corrected} if corrected else {})
    out = Path(args.out)
    text = commands_csv(machine, comp, labels)
    lines += said
    inputs["nominal_error_frame"] = where
    side = json_text(sidecar(machine, comp, inputs, program=not args.poses))
    write_files({out: text, out.with_suffix(".json"): side}, make_parents=True)  # both, or neither
    print(head)
    for line in lines:
        if line:
            print(line)
    for i in np.flatnonzero(~comp.reachable):
        print(f"pose_id {comp.pose_ids[i]}: {comp.problems[i]}", file=sys.stderr)
    print(f"wrote {out} and {out.with_suffix('.json')}")
    return EXIT_OK if comp.reachable.all() else EXIT_UNREACHABLE
