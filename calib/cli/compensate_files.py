"""What ``pkm-calib compensate`` writes: the commands CSV and its JSON sidecar."""

from __future__ import annotations

import csv
import io
from typing import Any

import numpy as np

from calib.compensate import Compensation, IdentifiedMachine

COLUMNS = {
    "predicted_residual_mm": "3D distance between the desired tool point and the one "
    "the identified model predicts at the written commands",
    "predicted_residual_deg": "angle between the desired tool frame and the predicted one",
    "predicted_error_nominal_mm": "3D error the identified model predicts for the "
    "nominal model's commands of the same pose (what compensation corrects), at the tool point",
    "predicted_error_nominal_reflectors_mm": "the same at the reflectors (RMS over them): what "
    "the tracker would measure; the tool point's is extrapolated from them",
}
PROGRAM_COLUMNS = {
    **COLUMNS,
    "predicted_error_nominal_mm": "3D error the identified model predicts for the "
    "program's own commands (what compensation corrects), at the tool point",
}
SEED_COLUMN = (
    "the program target (pose_id) whose configuration and orientation seeded the pose, or '--seed'"
)


def _fmt(value: float) -> str:
    return "" if not np.isfinite(value) else repr(float(value))


def _reflectors(comp: Compensation) -> np.ndarray:
    refl = comp.nominal_reflector_error_m
    return np.full(len(comp.pose_ids), np.nan) if refl is None else refl


def commands_csv(
    machine: IdentifiedMachine, comp: Compensation, seeds: list[str] | None = None
) -> str:
    """The rows of the reachable poses: pose_id, cmd:<actuator> (mm, deg), residuals (and
    the seed of each pose when ``seeds`` are given)."""
    mech = machine.nominal
    names = [f"cmd:{a}" for a in mech.actuator_names]
    tail = list(COLUMNS) + (["seed"] if seeds is not None else [])
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
                _fmt(_reflectors(comp)[i] * 1e3),
                *([seeds[i]] if seeds is not None else []),
            ]
        )
    return buf.getvalue()


def sidecar(
    machine: IdentifiedMachine, comp: Compensation, inputs: dict[str, Any], program: bool
) -> dict[str, Any]:
    """The JSON beside the commands: units, inputs (``inputs``: files, frame, seed), the
    targets not reachable and why, what each column means."""
    mech = machine.nominal
    ok = comp.reachable
    columns = dict(PROGRAM_COLUMNS if program else COLUMNS)
    if (inputs.get("seed") or {}).get("source") in ("program", "--seed"):
        columns["seed"] = SEED_COLUMN
    return {
        "format": "pkm-calib-commands",
        "version": 1,
        "model": mech.name,
        **inputs,
        "units": {
            f"cmd:{a}": "mm" if s else "deg"
            for a, s in zip(mech.actuator_names, mech.actuator_is_slide, strict=True)
        },
        "n_poses": len(comp.pose_ids),
        "n_written": int(ok.sum()),
        "unreachable": [
            {"pose_id": comp.pose_ids[i], "reason": comp.problems[i]} for i in np.flatnonzero(~ok)
        ],
        "columns": columns,
    }


def program_changes(machine: IdentifiedMachine, comp: Compensation) -> dict[str, Any]:
    """The largest change of each actuator's command from the program's (mm or deg) over the
    written targets, and where it is."""
    mech = machine.nominal
    ok = comp.reachable
    scale = np.where(mech.actuator_is_slide, 1e3, np.degrees(1.0))
    change = np.abs(comp.commands[ok] - comp.nominal_commands[ok]) * scale
    ids = [comp.pose_ids[i] for i in np.flatnonzero(ok)]
    out: dict[str, Any] = {}
    for k, a in enumerate(mech.actuator_names):
        if not len(ids):
            break
        j = int(np.argmax(change[:, k]))
        unit = "mm" if mech.actuator_is_slide[k] else "deg"
        out[a] = {"max": float(change[j, k]), "unit": unit, "pose_id": ids[j]}
    return out
