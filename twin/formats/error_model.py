"""A complete error model for any MJCF, so that no user writes one by hand.

    python -m twin.formats.error_model M.xml [--out M.params.toml]

For every body that carries a 1-DOF joint (hinge or slide), the six placement errors of the
body in its parent (``body_pos`` along and ``body_rot`` about the parent's x, y, z), less
the one that is the same as its first joint's own zero (the turn about a hinge axis, the
shift along a slide axis, when that axis is one of the parent's); for every actuated
joint, its zero offset (``joint_zero``); for every reflector (``target_*`` site) and every
site a closure is made at, its offset (``site_pos`` along the body's x, y, z; a weld fixes
both of its sites' frames to each other, so only its second site is given). Passive joints
get no zero (their value is solved: a zero offset moves nothing). Bodies without a joint
get nothing (their placement is their children's). Redundancy is left to the
identifiability analysis (``calib identify`` fixes what the poses cannot separate, and
says which partner absorbs it), as with any error model.

What this does not cover: the orientation of a weld's site frame (no kind of parameter
turns a site), joint axes inside a body with several joints beyond the first's placement.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from twin.exceptions import TwinError
from twin.mechanism import Mechanism
from twin.parameters import HINGE, SLIDE, Parameter, ParameterSet
from twin.rotations import matrix_from_quat

AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}
ALIGNED = 1e-12


@dataclass(frozen=True)
class Entry:
    name: str
    kind: str
    element: str
    axis: tuple[int, int, int] = (0, 0, 0)


def _name(m: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(m, obj, i) or ""


def _duplicate_axis(m: mujoco.MjModel, body: int) -> tuple[str, str] | None:
    """(kind, axis) of the placement error that equals the body's first joint's zero: the
    turn about a hinge axis or the shift along a slide axis, if that axis is one of the
    parent's coordinate axes."""
    joints = [j for j in range(m.njnt) if m.jnt_bodyid[j] == body]
    if not joints or int(m.jnt_type[joints[0]]) not in (HINGE, SLIDE):
        return None
    j = joints[0]
    in_parent = matrix_from_quat(m.body_quat[body]) @ m.jnt_axis[j]
    for c, a in AXES.items():
        if abs(abs(float(np.dot(in_parent, a))) - 1.0) < ALIGNED:
            return ("body_rot" if int(m.jnt_type[j]) == HINGE else "body_pos"), c
    return None


def _closure_sites(mech: Mechanism) -> list[int]:
    out: list[int] = []
    for c in mech.closures:
        sites = (c.site_b,) if c.kind == "weld" else (c.site_a, c.site_b)
        out += [s for s in sites if s not in out]
    return out


def error_entries(mech: Mechanism) -> list[Entry]:
    """The entries of the complete error model of ``mech``, in the order of the model."""
    m = mech.model
    site_names = {_name(m, mujoco.mjtObj.mjOBJ_SITE, s) for s in range(m.nsite)}
    moving = {int(m.jnt_bodyid[j]) for j in range(m.njnt) if int(m.jnt_type[j]) in (HINGE, SLIDE)}
    actuated = set(mech.actuator_joints.tolist())
    out: list[Entry] = []
    for b in range(1, m.nbody):
        if b not in moving:
            continue
        body = _name(m, mujoco.mjtObj.mjOBJ_BODY, b)
        if not body:
            raise TwinError(f"body {b} carries a joint but has no name: name it to give it errors")
        prefix = f"body:{body}" if body in site_names else body
        skip = _duplicate_axis(m, b)
        for kind, letter in (("body_pos", "d"), ("body_rot", "r")):
            for c, a in AXES.items():
                if skip != (kind, c):
                    out.append(Entry(f"{prefix}.{letter}{c}", kind, body, a))
        for j in range(m.njnt):
            if m.jnt_bodyid[j] == b and j in actuated:
                joint = _name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
                out.append(Entry(f"{joint}.zero", "joint_zero", joint))
    for s in [*_closure_sites(mech), *mech.target_sites.tolist()]:
        site = _name(m, mujoco.mjtObj.mjOBJ_SITE, s)
        out += [Entry(f"{site}.d{c}", "site_pos", site, a) for c, a in AXES.items()]
    return out


def error_parameters(mech: Mechanism) -> ParameterSet:
    """The complete error model of ``mech`` bound to its model."""
    return ParameterSet(
        [Parameter(e.name, e.kind, e.element, e.axis) for e in error_entries(mech)], mech.model
    )


def error_model_toml(mech: Mechanism, source: str) -> str:
    """The TOML text of the complete error model (``twin.formats.parameter_file`` reads it)."""
    entries = error_entries(mech)
    counts = {
        k: sum(e.kind == k for e in entries)
        for k in ("body_pos", "body_rot", "joint_zero", "site_pos")
    }
    lines = [
        f"# Complete error model of {mech.name} ({Path(source).name}), generated by",
        "# python -m twin.formats.error_model (its docstring says what each entry is). Values files give",  # noqa: E501
        "# these names in mm and deg. <body>.dx/dy/dz, .rx/ry/rz: the body's placement in its",
        "# parent's axes; <joint>.zero: an actuated joint's zero offset; <site>.dx/dy/dz: a",
        "# reflector's or closure site's offset in its body's axes.",
        f"# {len(entries)} parameters: {counts['body_pos']} offsets and {counts['body_rot']} "
        f"rotations of bodies, {counts['joint_zero']} joint zeros, {counts['site_pos']} site "
        "offsets.",
        "# Redundant ones are expected: identify fixes what the poses cannot separate.",
        f'model = "{mech.name}"',
        "",
    ]
    for e in entries:
        lines += [
            "[[parameter]]",
            f'name = "{e.name}"',
            f'kind = "{e.kind}"',
            f'element = "{e.element}"',
        ]
        if e.kind != "joint_zero":
            lines.append(f"axis = [{e.axis[0]}, {e.axis[1]}, {e.axis[2]}]")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="pkm-calib error-model", description=__doc__.split("\n")[0]
    )
    ap.add_argument("model", help="the MJCF of the machine")
    ap.add_argument("--out", help="where to write (default: beside the model, NAME.params.toml)")
    ap.add_argument("--force", action="store_true", help="replace an existing file")
    args = ap.parse_args(argv)
    try:
        mech = Mechanism.from_xml(args.model)
        text = error_model_toml(mech, args.model)
        error_parameters(mech)  # the generated model binds to the model it was made from
    except TwinError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    from common.atomic_files import write_text_atomic  # the project's one atomic writer

    model = Path(args.model)
    out = Path(args.out) if args.out else model.with_name(f"{model.stem}.params.toml")
    if out.resolve() == model.resolve():
        print("error: --out is the model itself", file=sys.stderr)
        return 2
    if out.exists() and not args.force:
        print(
            f"error: {out} exists (an error model of yours?): give --out or --force",
            file=sys.stderr,
        )
        return 2
    write_text_atomic(out, text)
    print(f"wrote {out}: {text.count('[[parameter]]')} parameters")
    return 0


error_model_command = main  # pkm-calib error-model (pkm_calib.command)

if __name__ == "__main__":
    raise SystemExit(main())
