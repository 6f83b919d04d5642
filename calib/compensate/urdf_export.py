"""The calibrated URDF of a model generated from a URDF (``pkm-calib export --urdf-out``).

The identified geometry goes into the URDF's joint origins and the joint zeros are folded into
them (twin.formats.urdf_values); the written URDF is read back as the project reads any URDF
(twin.formats.urdf_import, twin.formats.from_urdf with the identified reflectors and tool on
their links) and its forward kinematics compared with the identified model's at the same joint
values, to ``FK_TOLERANCE_M``. The URDF given must be the model's own: its nominal model is
compared with the MJCF the same way first. What a URDF cannot hold (reflector and tool offsets,
actuator gains, compliances, any other kind) goes into its sidecar and its header.
"""

from __future__ import annotations

import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from calib.compensate.identified_machine import IdentifiedMachine
from calib.compensate.sidecar import not_held, sidecar_path, sidecar_text
from calib.exceptions import CalibError
from twin.exceptions import TwinError
from twin.formats.from_urdf import SiteSpec, build_xml
from twin.formats.urdf_import import read_urdf
from twin.formats.urdf_values import urdf_with_model
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism

URDF_KINDS = ("body_pos", "body_rot", "joint_zero")  # what a URDF's joint origins hold
_SOURCE = re.compile(r"from the URDF (\S+) \(robot")


class UrdfExportError(CalibError):
    """The calibrated URDF cannot be written (the message says why); nothing was written."""


@dataclass(frozen=True)
class UrdfExport:
    text: str
    sidecar: Path
    sidecar_text: str
    not_held: list[dict]
    nominal_m: float  # the URDF's nominal model against the MJCF (m)
    calibrated_m: float  # the written URDF against the identified model (m)


def source_urdf(model_path: Path, urdf: str | os.PathLike[str] | None) -> Path:
    """``urdf``, else the URDF the model's header names (pkm-calib from-urdf),
    beside the model."""
    if urdf is not None:
        return Path(urdf)
    found = _SOURCE.search(model_path.read_text(encoding="utf-8", errors="replace")[:2000])
    if found and (model_path.parent / found.group(1)).is_file():
        return model_path.parent / found.group(1)
    raise UrdfExportError(
        f"{model_path} names no URDF beside it that it was generated from: give --urdf"
    )


def _sites(mech: Mechanism) -> list[SiteSpec]:
    m = mech.model
    out = []
    for s in (mech.tool_site, *mech.target_sites):
        link = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.site_bodyid[s]))
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, int(s))
        out.append(SiteSpec(name, link, tuple(m.site_pos[s]), tuple(m.site_quat[s])))
    return out


def _urdf_mechanism(path: Path, name: str, like: Mechanism) -> Mechanism:
    """The model the project makes of the URDF at ``path``, with ``like``'s tool and
    reflectors on the same links."""
    return Mechanism.from_xml_string(build_xml(read_urdf(path), name, _sites(like)))


def _difference(a: Mechanism, b: Mechanism, joints: np.ndarray) -> float:
    """The largest distance (m) of a target or the tool point of ``a`` and ``b`` at the same
    joint values."""
    fa, fb = forward_batch(a, joints, check_stroke=False), forward_batch(b, joints)
    points = np.concatenate(
        [fa.targets - fb.targets, (fa.tool_position - fb.tool_position)[:, None]], 1
    )
    return float(np.max(np.linalg.norm(points, axis=-1)))


def calibrated_urdf(
    machine: IdentifiedMachine, urdf: Path, out: Path, probes: np.ndarray, tolerance: float
) -> UrdfExport:
    """The calibrated URDF's text and sidecar, checked (see the module's docstring)."""
    joints = machine.nominal.joints_of_commands(probes)
    try:
        nominal_m = _difference(
            machine.nominal, _urdf_mechanism(urdf, machine.nominal.name, machine.nominal), joints
        )
    except TwinError as exc:
        raise UrdfExportError(f"--urdf {urdf}: {exc}") from None
    if not nominal_m <= tolerance:
        raise UrdfExportError(
            f"{urdf} is not the URDF the model was generated from: their forward kinematics "
            f"differ by {nominal_m * 1e3:.3g} mm"
        )
    missing = not_held(machine, URDF_KINDS)
    header = (
        f"Calibrated URDF of '{machine.nominal.name}': {urdf.name} with the geometry identified "
        f"in {machine.result.path.name} in its joint origins (joint zeros folded in), written "
        f"by pkm-calib export. "
        + (
            f"A URDF cannot hold {len(missing)} identified parameter(s) (reflector and tool "
            f"offsets, actuator gains, ...): listed in {sidecar_path(out).name}: "
            + ", ".join(f"{m['name']} {m['value']:.6g} {m['unit']}" for m in missing)
            if missing
            else "It holds every identified parameter."
        )
    )
    mech = machine.mechanism
    text = urdf_with_model(urdf, mech.model, header)
    fd, name = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.", suffix=".urdf")
    os.close(fd)
    tmp = Path(name)
    try:
        tmp.write_text(text, encoding="utf-8")
        calibrated_m = _difference(mech, _urdf_mechanism(tmp, machine.nominal.name, mech), joints)
    finally:
        tmp.unlink(missing_ok=True)
    if not calibrated_m <= tolerance:
        raise UrdfExportError(
            f"the written URDF's forward kinematics differs from the identified model's by "
            f"{calibrated_m * 1e3:.3g} mm (more than {tolerance * 1e3:g} mm): nothing written"
        )
    held = {
        "joint_origins": int(
            np.sum(np.isin([p.kind for p in machine.model.params.parameters], URDF_KINDS))
        )
    }
    side = sidecar_path(out)
    return UrdfExport(
        text,
        side,
        sidecar_text(machine, out, urdf, missing, held),
        missing,
        nominal_m,
        calibrated_m,
    )
