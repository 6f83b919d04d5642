"""The kinds of error-model parameter, and the units of those that are not lengths or angles.

Geometry (``body_pos``, ``body_rot``, ``site_pos``, ``joint_zero``) is in metres and radians
inside, millimetres and degrees in files. The kinds that act through the commands have their
own units (twin.parameters says what each means):

* ``actuator_gain``: dimensionless inside, ppm in files;
* ``joint_compliance``: rad/(N m) or m/N inside (a revolute or a prismatic actuator),
  deg/(kN m) or mm/kN (= um/N) in files: the units in which the diagnosis reports its
  ``gravity_compliance`` candidate. Without a ``payload_kg`` the value is a compliance times
  the payload's mass, and each unit reads " kg" more (deg/(kN m) kg, mm/kN kg), as the
  diagnosis prints it on a model without declared masses.

The functions take a ParameterSet (``is_angle``, ``is_gain``, ``is_compliance``, ``turns``,
``payload_kg``), whose methods of the same names call them.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from twin.exceptions import ParameterError
from twin.offset_kinds import OFFSET_KINDS, offset_factor, offset_units

KINDS = (
    "body_pos",
    "body_rot",
    "site_pos",
    "joint_zero",
    "actuator_gain",
    "joint_compliance",
    *OFFSET_KINDS,
)
GAIN = KINDS.index("actuator_gain")
COMPLIANCE = KINDS.index("joint_compliance")
# act through the commands (the offsets: twin.offset_kinds)
ACTUATION_KINDS = ("actuator_gain", "joint_compliance", *OFFSET_KINDS)
# display value per SI value of a compliance: deg/(kN m) per rad/(N m), mm/kN per m/N
TURNING_FACTOR = float(np.degrees(1.0)) * 1e3
SLIDING_FACTOR = 1e6


def check_payload(name: str, kind: str, payload_kg: object) -> None:
    """A ``payload_kg`` belongs to a joint compliance and is a finite mass >= 0 (kg)."""
    if payload_kg is None:
        return
    if kind != "joint_compliance":
        raise ParameterError(
            f"parameter '{name}': payload_kg belongs to a joint_compliance, not to a {kind}"
        )
    if (
        isinstance(payload_kg, (bool, np.bool_))
        or not isinstance(payload_kg, (int, float, np.number))
        or not np.isfinite(payload_kg)
        or payload_kg < 0
    ):
        raise ParameterError(
            f"parameter '{name}': payload_kg must be a finite mass >= 0 (kg), got {payload_kg!r}"
        )


def _compliance_units(params: Any, out: list[str], turning: str, sliding: str) -> list[str]:
    for k in np.flatnonzero(params.is_compliance):
        per_kg = " kg" if np.isnan(params.payload_kg[k]) else ""
        out[k] = (turning if params.turns[k] else sliding) + per_kg
    return out


def si_units(params: Any) -> list[str]:
    """SI unit of each parameter: "m", "rad", "1" for a (dimensionless) gain, a compliance's
    "rad/(N m)" or "m/N" (with " kg" per kg of payload)."""
    out = [
        "1" if g else "rad" if a else "m"
        for a, g in zip(params.is_angle, params.is_gain, strict=True)
    ]
    return _offset_units(params, _compliance_units(params, out, "rad/(N m)", "m/N"), True)


def _offset_units(params: Any, out: list[str], si: bool) -> list[str]:
    for k in np.flatnonzero(getattr(params, "is_offset", ())):
        p = params.parameters[k]
        out[k] = offset_units(p.kind, bool(params.turns[k]), p.constants_dict, si)
    return out


def _offset_factors(params: Any) -> np.ndarray:
    """Display value per SI value of each parameter that is an offset kind (1 elsewhere)."""
    out = np.ones(len(params.kind))
    for k in np.flatnonzero(params.is_offset):
        out[k] = offset_factor(params.parameters[k].kind, bool(params.turns[k]))
    return out


def display_units(params: Any) -> list[str]:
    """Unit of each parameter in files, results and printouts: "mm", "deg", "ppm", a
    compliance's "deg/(kN m)" or "mm/kN" (with " kg" per kg of payload)."""
    out = [
        "ppm" if g else "deg" if a else "mm"
        for a, g in zip(params.is_angle, params.is_gain, strict=True)
    ]
    return _offset_units(params, _compliance_units(params, out, "deg/(kN m)", "mm/kN"), False)


def _compliance_factor(params: Any) -> np.ndarray:
    return np.where(params.turns, TURNING_FACTOR, SLIDING_FACTOR)


def to_display(params: Any, values: np.ndarray) -> np.ndarray:
    """SI -> millimetres, degrees, ppm and the compliances' units, per parameter (the
    geometry's and the gains' arithmetic unchanged by the compliances)."""
    v = np.asarray(values, dtype=float)
    shown = np.where(params.is_angle, np.degrees(v), v * 1e3)
    shown = np.where(params.is_gain, v * 1e6, shown) if params.has_gains else shown
    if params.has_compliance:
        shown = np.where(params.is_compliance, v * _compliance_factor(params), shown)
    if np.any(getattr(params, "is_offset", False)):
        shown = np.where(params.is_offset, v * _offset_factors(params), shown)
    return shown


def from_display(params: Any, values: Iterable[float]) -> np.ndarray:
    """Millimetres, degrees, ppm and the compliances' units -> SI, per parameter."""
    v = np.asarray(list(values), dtype=float)
    si = np.where(params.is_angle, np.radians(v), v * 1e-3)
    si = np.where(params.is_gain, v * 1e-6, si) if params.has_gains else si
    if params.has_compliance:
        si = np.where(params.is_compliance, v / _compliance_factor(params), si)
    if np.any(getattr(params, "is_offset", False)):
        si = np.where(params.is_offset, v / _offset_factors(params), si)
    return si
