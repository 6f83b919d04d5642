"""What an exported model cannot hold, written beside it (``M.xml``: ``M.xml.calibration.json``).

``pkm-calib export`` writes the identified geometry and the actuator gains into the MJCF
(twin.formats.mjcf_values). Every other identified parameter, whatever its kind (a joint
compliance today; any kind an MJCF has no attribute for), is listed in the sidecar with its
kind, element, value and unit and why the model cannot hold it, together with the result it
came from and whether the result had a tracker registration (never part of a model). The
sidecar is written with the model, every time (so that no earlier export's sidecar outlives
it), and the result's residual correction (calib.correction) in full, which a user's
controller adds to the model's prediction inside its calibrated region. ``verify --model
M_cal.xml`` reads it and says in its first line what the model lacks:
scored as it is, the model predicts without those parameters.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from calib.compensate.identified_machine import IdentifiedMachine

SIDECAR_SUFFIX = ".calibration.json"
FORMAT = "calib-export-sidecar/1"
# why an MJCF file holds no parameter of a kind (a kind not named: no MJCF attribute means it)
WHY_NOT_HELD = {
    "joint_compliance": (
        "a joint that yields to its gravity load by a fixed compliance is no MJCF attribute: "
        "a joint's stiffness acts only in MuJoCo's dynamics, on the model's masses, whereas the "
        "compliance was identified on the static load the calibration computes (per kg of "
        "payload without declared masses)"
    ),
}


def sidecar_path(model_path: str | Path) -> Path:
    """The sidecar of the model file ``model_path``."""
    p = Path(model_path)
    return p.with_name(p.name + SIDECAR_SUFFIX)


def not_held(machine: IdentifiedMachine, held_kinds: tuple[str, ...]) -> list[dict[str, Any]]:
    """The identified parameters whose kind is not in ``held_kinds`` (SI -> display units)."""
    params = machine.model.params
    shown, units = params.to_display(machine.values), params.display_units()
    out = []
    for k, p in enumerate(params.parameters):
        if p.kind in held_kinds:
            continue
        entry: dict[str, Any] = {
            "name": p.name,
            "kind": p.kind,
            "element": p.element,
            "value": float(shown[k]),
            "unit": units[k],
            "why": WHY_NOT_HELD.get(p.kind, f"an MJCF file has no attribute for a {p.kind}"),
        }
        if not np.isnan(params.payload_kg[k]):
            entry["payload_kg"] = float(params.payload_kg[k])
        out.append(entry)
    return out


def sidecar_text(
    machine: IdentifiedMachine,
    model_file: Path,
    nominal_file: Path,
    missing: list[dict[str, Any]],
    held: dict[str, Any],
) -> str:
    """The sidecar's JSON text."""
    content = {
        "format": FORMAT,
        "model": model_file.name,
        "machine": machine.nominal.name,
        "nominal_model": str(nominal_file),
        "result": str(machine.result.path),
        "held_in_model": held,
        "not_held": missing,
        # the result's residual correction (calib.correction), which no model file holds:
        # the model's prediction plus it, inside its calibrated region, is the calibration's
        "residual_correction": machine.result.data.get("residual_correction"),
        "tracker_registration": (
            None
            if machine.registration is None
            else "the result's tracker registration is not part of the model: readings in the "
            "tracker's frame are registered again when the model is verified"
        ),
    }
    return json.dumps(content, indent=2) + "\n"


def missing_line(model_path: str | Path) -> str | None:
    """The warning about what the model at ``model_path`` lacks, from its sidecar; None
    without a sidecar or when it lacks nothing."""
    path = sidecar_path(model_path)
    if not path.is_file():
        return None
    try:
        content = json.loads(path.read_text(encoding="utf-8"))
        missing = content["not_held"]
        names = [f"{m['name']} ({m['kind']}, {m['value']:.6g} {m['unit']})" for m in missing]
        corrected = bool(content.get("residual_correction"))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return (
            f"WARNING: {path} (what this model lacks) cannot be read ({exc}): the model may "
            "lack identified parameters"
        )
    if not names and not corrected:
        return None
    lacks = f"{len(names)} identified parameter(s) its file cannot hold" if names else ""
    if corrected:
        lacks += (" and " if lacks else "") + "the result's residual correction"
    return (
        f"WARNING: this model lacks {lacks} (listed in {path.name})"
        + (f": {', '.join(names)}" if names else "")
        + "; scored as it is, it predicts without "
        f"them (verify --model {content.get('nominal_model', 'NOMINAL.xml')} --errors E.toml "
        f"--result {content.get('result', 'R.json')} scores the whole result)"
    )
