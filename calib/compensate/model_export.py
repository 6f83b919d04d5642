"""The calibrated model as files a controller or simulator takes: MJCF and DH table.

The nominal MJCF with the identified errors written into its geometry (twin.formats.mjcf_values),
compiled again and its forward kinematics compared with the identified model's at commands
spread over what the machine reaches: the file is written only if they agree to
``FK_TOLERANCE_M``. For a model generated from a DH table, the calibrated table as well
(twin.formats.dh_extract). Nothing is written when any part fails.

Actuator gains (``identify --with`` a diagnosis that named them) are no geometry: an MJCF
joint's value is its command. The file then holds the identified geometry, its kinematics
is checked in joint values, and the gains are named in its header and the command's
output for the controller to apply (joint = zero + (command - zero)(1 + gain)).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.compensate.identified_machine import IdentifiedMachine
from calib.exceptions import CalibError
from common.write_set import write_files
from twin.exceptions import ClosureError, WorkspaceError
from twin.formats.dh_extract import dh_table_of, format_dh_table
from twin.formats.mjcf_values import WrittenMjcf, mjcf_with_values, with_header
from twin.kinematics.batch import forward_batch
from twin.kinematics.single_pose import forward
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet
from twin.rotations import rotation_angle
from twin.workspace import random_poses

FK_TOLERANCE_M = 1e-9
N_PROBES = 24
PROBE_SEED = 20261126  # fixed: the same commands every run


class ExportError(CalibError):
    """The calibrated model cannot be written (the message says why); nothing was written."""


@dataclass(frozen=True)
class KinematicsCheck:
    """Forward kinematics of two models of a machine compared at the same commands."""

    n_commands: int
    max_position_m: float  # largest 3D distance of a target or the tool point
    max_rotation_rad: float  # largest angle between the two tool frames

    def as_dict(self) -> dict[str, float | int]:
        return {
            "n_commands": self.n_commands,
            "max_fk_diff_mm": self.max_position_m * 1e3,
            "max_tool_rotation_diff_deg": float(np.degrees(self.max_rotation_rad)),
        }


def _closes(mech: Mechanism, commands: np.ndarray) -> bool:
    try:
        forward(mech, commands)
    except (ClosureError, WorkspaceError):
        return False
    return True


def probe_commands(mech: Mechanism, n: int = N_PROBES, seed: int = PROBE_SEED) -> np.ndarray:
    """Home and ``n`` commands spread over what ``mech`` reaches (a fixed seed): random
    reachable poses of a declared workspace, else uniform over the strokes for a serial
    chain, else commands about home that close."""
    rng = np.random.default_rng(seed)
    home = mech.home_qpos[mech.actuator_qpos]
    lo, hi = mech.actuator_range.T
    if mech.workspace_min is not None and mech.workspace_max is not None:
        return np.vstack([home, random_poses(mech, n, rng)[1]])
    span_lo = np.where(np.isfinite(lo), lo, home - np.where(mech.actuator_is_slide, 0.1, np.pi))
    span_hi = np.where(np.isfinite(hi), hi, home + np.where(mech.actuator_is_slide, 0.1, np.pi))
    if mech.is_serial:
        return np.vstack([home, rng.uniform(span_lo, span_hi, (n, mech.n_actuators))])
    out = [home]
    for scale in (0.25, 0.1, 0.03):  # about home, smaller until they close
        for c in home + scale * rng.uniform(span_lo - home, span_hi - home, (n, len(home))):
            if len(out) <= n and _closes(mech, c):
                out.append(c)
    return np.array(out)


def kinematics_difference(a: Mechanism, b: Mechanism, commands: np.ndarray) -> KinematicsCheck:
    """The largest differences of targets, tool point and tool frame between ``a`` and
    ``b`` at ``commands`` (N, A) (SI)."""
    fa, fb = forward_batch(a, commands), forward_batch(b, commands)
    points = np.concatenate(
        [fa.targets - fb.targets, (fa.tool_position - fb.tool_position)[:, None]], 1
    )
    turn = rotation_angle(np.swapaxes(fa.tool_rotation, -1, -2) @ fb.tool_rotation)
    return KinematicsCheck(
        len(commands), float(np.max(np.linalg.norm(points, axis=-1))), float(np.max(turn))
    )


def geometry(machine: IdentifiedMachine) -> tuple[ParameterSet, np.ndarray]:
    """The identified machine's geometric parameters and their values (the gains and
    compliances left out)."""
    params, values = machine.model.params, machine.values
    if params.is_geometry:
        return params, values
    keep = params.is_geometric
    chosen = [p for p, k in zip(params.parameters, keep, strict=True) if k]
    return ParameterSet(chosen, machine.nominal.model), values[keep]


def gains_text(machine: IdentifiedMachine) -> str | None:
    """The identified actuator gains (ppm) and joint compliances in words, or None without
    any."""
    params = machine.model.params
    if params.is_geometry:
        return None
    shown, units = params.to_display(machine.values), params.display_units()
    texts = []
    if params.has_gains:
        parts = [
            f"{params.parameters[k].element} {shown[k]:+.4g} ppm"
            for k in np.flatnonzero(params.is_gain)
        ]
        texts.append(
            "actuator gains, no geometry and so not in the MJCF (the controller applies them: "
            "joint = zero + (command - zero)(1 + gain)): " + ", ".join(parts)
        )
    if params.has_compliance:
        parts = [
            f"{params.parameters[k].element} {shown[k]:+.4g} {units[k]}"
            + (
                ""
                if np.isnan(params.payload_kg[k])
                else f" (own masses and {params.payload_kg[k]:g} kg at the tool)"
            )
            for k in np.flatnonzero(params.is_compliance)
        ]
        texts.append(
            "joint compliances, no geometry and so not in the MJCF (the joints yield to their "
            "gravity load: joint = command - compliance x load): " + ", ".join(parts)
        )
    return "; the ".join(texts)


def calibrated_mjcf(
    machine: IdentifiedMachine, model_path: str | Path, out_dir: str | Path | None = None
) -> WrittenMjcf:
    """The nominal MJCF text with the identified geometry written in (no header)."""
    params, values = geometry(machine)
    return mjcf_with_values(
        model_path,
        machine.nominal.model,
        params,
        values,
        out_dir=out_dir,
        bound_masses=machine.nominal.masses_defaulted,
    )


@dataclass(frozen=True)
class Export:
    out: Path
    dh_out: Path | None
    written: WrittenMjcf
    check: KinematicsCheck


def _header(machine: IdentifiedMachine, model_path: Path, w: WrittenMjcf, c: KinematicsCheck):
    return (
        f"Calibrated model of '{machine.nominal.name}': {model_path.name} with the errors "
        f"identified in {machine.result.path.name} written into its geometry by python -m "
        f"calib export ({len(w.bodies)} bodies placed anew, {len(w.sites)} sites moved, "
        f"{len(w.joints)} joint zeros shifted as 'ref'). Its forward kinematics differs from "
        f"the identified model's by at most {c.max_position_m * 1e3:.3g} mm over "
        f"{c.n_commands} commands."
        + (
            " The masses are MuJoCo's bounded defaults (kinematics only)."
            if machine.nominal.masses_defaulted
            else ""
        )
        + (
            " The tracker registration of the result is not part of the model."
            if machine.registration is not None
            else ""
        )
        + (f" The {gains_text(machine)}." if not machine.model.params.is_geometry else "")
    )


def calibrated_dh_text(machine: IdentifiedMachine, model_path: Path) -> str:
    """The calibrated DH table of a model generated from one (twin.formats.dh_extract)."""
    table = dh_table_of(machine.mechanism.model, source=str(model_path))
    return format_dh_table(
        table,
        (
            f"calibrated DH table of '{machine.nominal.name}' ({model_path.name}) with the "
            f"errors identified in {machine.result.path.name}, written by python -m calib export",
            "the joint value q is the commanded value, as before: theta (R) and d (P) include "
            "the identified encoder offsets",
            f"generate its model: python -m twin.formats.dh_table THIS.csv --name "
            f"{machine.nominal.name} --out-dir DIR",
        ),
    )


def export_model(
    machine: IdentifiedMachine,
    model_path: str | os.PathLike[str],
    out: str | os.PathLike[str],
    dh_out: str | os.PathLike[str] | None = None,
    commands: np.ndarray | None = None,
) -> Export:
    """Write the calibrated MJCF to ``out`` (and the calibrated DH table to ``dh_out``)
    after checking the written model's kinematics against the identified one at
    ``commands`` (default: :func:`probe_commands`); nothing is written if a part fails."""
    model_path, out = Path(model_path), Path(out)
    if out.resolve() == model_path.resolve():
        raise ExportError(f"--out {out} is the nominal model itself: choose another file")
    dh_text = None if dh_out is None else calibrated_dh_text(machine, model_path)
    written = calibrated_mjcf(machine, model_path, out.parent)
    probes = probe_commands(machine.nominal) if commands is None else np.asarray(commands)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.", suffix=".xml")
    os.close(fd)
    tmp = Path(name)  # beside the output, so that relative mesh paths resolve
    try:
        tmp.write_text(written.text, encoding="utf-8")
        exported = Mechanism.from_xml(tmp)
    finally:
        tmp.unlink(missing_ok=True)
    check = kinematics_difference(machine.mechanism, exported, probes)
    if not check.max_position_m <= FK_TOLERANCE_M:
        raise ExportError(
            f"the written model's forward kinematics differs from the identified model's "
            f"by {check.max_position_m * 1e3:.3g} mm (more than "
            f"{FK_TOLERANCE_M * 1e3:g} mm): nothing written"
        )
    header = _header(machine, model_path, written, check)
    files = {out: with_header(written.text, header)}
    if dh_text is not None:
        files[Path(dh_out)] = dh_text
    write_files(files)  # the model and its DH table together, or neither
    return Export(out, None if dh_out is None else Path(dh_out), written, check)
