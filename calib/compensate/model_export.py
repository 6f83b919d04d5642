"""The calibrated model as files a controller or simulator takes: MJCF and DH table.

The nominal MJCF with the identified errors written into its geometry (twin.formats.mjcf_values),
compiled again and its forward kinematics compared with the identified model's at commands
spread over what the machine reaches: the file is written only if they agree to
``FK_TOLERANCE_M``. For a model generated from a DH table, the calibrated table as well
(twin.formats.dh_extract). Nothing is written when any part fails.

Actuator gains (``identify --with`` a diagnosis that named them) go into the actuators' gears
and their joints' zeros (twin.formats.mjcf_values): a command c sets the joint to
zero + (c - zero)(1 + gain), as in the identified model, and the check compares the two at
the same commands. What the MJCF cannot hold (joint compliances, any kind without an MJCF
attribute) is written beside it (calib.compensate.sidecar), and the check then compares
the written model with the identified one without those parameters.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.compensate.identified_machine import IdentifiedMachine
from calib.compensate.sidecar import not_held, sidecar_path, sidecar_text
from calib.compensate.urdf_export import UrdfExport, calibrated_urdf, source_urdf
from calib.exceptions import CalibError
from common.write_set import write_files
from twin.exceptions import ClosureError, WorkspaceError
from twin.formats.dh_extract import dh_table_of, format_dh_table
from twin.formats.mjcf_values import (
    WRITABLE_KINDS,
    WrittenMjcf,
    mjcf_with_values,
    with_header,
)
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


def kinematics_difference(
    a: Mechanism, b: Mechanism, commands: np.ndarray, a_commands: np.ndarray | None = None
) -> KinematicsCheck:
    """The largest differences of targets, tool point and tool frame between ``a`` and
    ``b`` at ``commands`` (N, A) (SI); ``a_commands``: ``a``'s inputs for them, if others
    (the joint values the commands give in an identified model with gains)."""
    a_in = commands if a_commands is None else a_commands
    fa, fb = forward_batch(a, a_in, check_stroke=a_commands is None), forward_batch(b, commands)
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


def gain_scales(machine: IdentifiedMachine) -> dict[str, float]:
    """1 + gain per gained actuator's name (empty without gains)."""
    gains = machine.model.gains
    if gains is None:
        return {}
    g, scale = gains.gains(machine.values), gains.scale(machine.values)
    names = machine.nominal.actuator_names
    return {names[a]: float(scale[a]) for a in np.flatnonzero(g != 0.0)}


def gained_joints(machine: IdentifiedMachine, commands: np.ndarray) -> np.ndarray:
    """The joint values (N, A) the commands give through the identified gains alone (what
    the exported model holds; its compliances are not)."""
    gains = machine.model.gains
    if gains is None:
        return np.asarray(commands, dtype=float)
    return gains.joints(machine.values, commands, machine.model.joint_zeros(machine.values))


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
            "actuator gains, in the actuators' gear (1 / (1 + gain)) and their joints' zero "
            "(ref), so that a command sets the joint to zero + (command - zero)(1 + gain): "
            + ", ".join(parts)
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
            "joint compliances, which an MJCF cannot hold (the joints yield to their gravity "
            "load: joint = command - compliance x load), in the sidecar: " + ", ".join(parts)
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
        scales=gain_scales(machine),
    )


@dataclass(frozen=True)
class Export:
    out: Path
    dh_out: Path | None
    written: WrittenMjcf
    check: KinematicsCheck
    sidecar: Path
    not_held: list[dict]  # the parameters the model cannot hold (in the sidecar)
    urdf_out: Path | None = None
    urdf: UrdfExport | None = None


def _header(
    machine: IdentifiedMachine,
    model_path: Path,
    w: WrittenMjcf,
    c: KinematicsCheck,
    missing: list[dict],
    side: Path,
) -> str:
    return (
        f"Calibrated model of '{machine.nominal.name}': {model_path.name} with the errors "
        f"identified in {machine.result.path.name} written into its geometry by pkm-calib "
        f"export ({len(w.bodies)} bodies placed anew, {len(w.sites)} sites moved, "
        f"{len(w.joints)} joint zeros shifted as 'ref', {len(w.actuators)} actuator gains as "
        f"'gear'). Its forward kinematics differs from the identified model's by at most "
        f"{c.max_position_m * 1e3:.3g} mm over {c.n_commands} commands."
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
        + (
            f" It lacks {len(missing)} identified parameter(s) an MJCF cannot hold, listed "
            f"in {side.name}: the check above is without them."
            if missing
            else ""
        )
    )


def calibrated_dh_text(machine: IdentifiedMachine, model_path: Path) -> str:
    """The calibrated DH table of a model generated from one (twin.formats.dh_extract)."""
    table = dh_table_of(machine.mechanism.model, source=str(model_path))
    return format_dh_table(
        table,
        (
            f"calibrated DH table of '{machine.nominal.name}' ({model_path.name}) with the "
            f"errors identified in {machine.result.path.name}, written by pkm-calib export",
            "the joint value q is the commanded value, as before: theta (R) and d (P) include "
            "the identified encoder offsets",
            f"generate its model: pkm-calib from-dh THIS.csv --name "
            f"{machine.nominal.name} --out-dir DIR",
            *(
                [
                    f"not in this table: the {gains_text(machine)}; the calibrated MJCF "
                    "holds the gains"
                ]
                if machine.model.params.has_gains
                else []
            ),
        ),
    )


def export_model(
    machine: IdentifiedMachine,
    model_path: str | os.PathLike[str],
    out: str | os.PathLike[str],
    dh_out: str | os.PathLike[str] | None = None,
    commands: np.ndarray | None = None,
    urdf_out: str | os.PathLike[str] | None = None,
    urdf: str | os.PathLike[str] | None = None,
) -> Export:
    """Write the calibrated MJCF to ``out`` and its sidecar (and the calibrated DH table to
    ``dh_out``, the calibrated URDF of the model's URDF ``urdf`` (default: the one its header
    names) to ``urdf_out`` with its sidecar) after checking the written models' kinematics
    against the identified one at ``commands`` (default: :func:`probe_commands`); nothing is
    written if a part fails."""
    model_path, out = Path(model_path), Path(out)
    if out.resolve() == model_path.resolve():
        raise ExportError(f"--out {out} is the nominal model itself: choose another file")
    dh_text = None if dh_out is None else calibrated_dh_text(machine, model_path)
    written = calibrated_mjcf(machine, model_path, out.parent)
    probes = probe_commands(machine.nominal) if commands is None else np.asarray(commands)
    missing = not_held(machine, (*WRITABLE_KINDS, "actuator_gain"))
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.", suffix=".xml")
    os.close(fd)
    tmp = Path(name)  # beside the output, so that relative mesh paths resolve
    try:
        tmp.write_text(written.text, encoding="utf-8")
        exported = Mechanism.from_xml(tmp)
    except OSError as exc:  # a full disk: said with the file, not as a raw errno
        raise ExportError(
            f"cannot write {tmp} (the calibrated model, read back to check it): "
            f"{exc.strerror or exc}; nothing written"
        ) from None
    finally:
        tmp.unlink(missing_ok=True)
    check = kinematics_difference(
        machine.mechanism, exported, probes, gained_joints(machine, probes)
    )
    if not check.max_position_m <= FK_TOLERANCE_M:
        raise ExportError(
            f"the written model's forward kinematics differs from the identified model's "
            f"by {check.max_position_m * 1e3:.3g} mm (more than "
            f"{FK_TOLERANCE_M * 1e3:g} mm): nothing written"
        )
    side = sidecar_path(out)
    header = _header(machine, model_path, written, check, missing, side)
    held = {"geometry": len(geometry(machine)[0]), "actuator_gains": list(written.actuators)}
    files = {
        out: with_header(written.text, header),
        side: sidecar_text(machine, out, model_path, missing, held),
    }
    if dh_text is not None:
        files[Path(dh_out)] = dh_text
    done_urdf = None
    if urdf_out is not None:
        urdf_out = Path(urdf_out)
        if sidecar_path(urdf_out) == side:
            raise ExportError(f"--urdf-out {urdf_out} and --out {out} would share one sidecar")
        urdf_out.parent.mkdir(parents=True, exist_ok=True)
        source = source_urdf(model_path, urdf)
        done_urdf = calibrated_urdf(machine, source, urdf_out, probes, FK_TOLERANCE_M)
        files[urdf_out] = done_urdf.text
        files[done_urdf.sidecar] = done_urdf.sidecar_text
    write_files(files)  # the models, their sidecars and the DH table together, or none
    dh = None if dh_out is None else Path(dh_out)
    return Export(out, dh, written, check, side, missing, urdf_out, done_urdf)
