"""The diagnosis's effects that offset the joint values, as parameters of the error model.

``diagnose --out`` writes them into ``effect.added_parameters`` beside the static kinds
(calib.loop.effect_kinds), with the shape the diagnosis found as the parameters' constants
(twin.offset_kinds):

* ``lead_error``            one ``periodic_error`` sine and cosine per prismatic actuator at
                            the pitch found (``period_mm``)
* ``encoder_eccentricity``  one ``periodic_error`` sine and cosine per revolute actuator at
                            the harmonic found (``harmonic``)
* ``backlash``              one ``backlash`` (half the play) per actuator
* ``thermal_growth``        one ``thermal_growth`` per prismatic actuator (the diagnosis
                            fits one strain for all: each actuator gets its own here)
* ``zero_drift``            one ``drift`` per actuator

the time kinds on the diagnosis's clock (``time_s`` when the dataset has it, else ``order``),
from its time origin, with its time constant (none when it found an infinite one: linear).
"""

from __future__ import annotations

from typing import Any

from calib.exceptions import CalibError
from twin.parameters import Parameter

OFFSET_EFFECTS = ("lead_error", "encoder_eccentricity", "backlash", "thermal_growth", "zero_drift")


class OffsetEffectError(CalibError):
    """A diagnosis's fit that lacks what the error-model parameters need."""


def _shape(fitted: dict[str, Any], key: str, effect: str) -> float | None:
    entry = fitted.get(key) or {}
    value = entry.get("value")
    if value == "inf":
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise OffsetEffectError(f"the diagnosis's {effect} has no {key} to write")
    return float(value)


def offset_parameters(
    effect: str,
    actuators: tuple[str, ...],
    is_slide: tuple[bool, ...],
    fitted: dict[str, Any] | None,
    clock: str,
    origin: float,
    have: set[str],
) -> list[Parameter]:
    """The parameters that carry ``effect`` (one of OFFSET_EFFECTS), named as the diagnosis
    names its own; ``fitted``: its ``effect_parameters`` entry (the shape in display units:
    pitch mm, harmonic, time constant in the clock's unit); ``have``: names already in the
    error model, left out."""
    fitted = fitted or {}
    out: list[Parameter] = []
    slides = [a for a, s in zip(actuators, is_slide, strict=True) if s]
    turning = [a for a, s in zip(actuators, is_slide, strict=True) if not s]
    if effect in ("lead_error", "encoder_eccentricity"):
        lead = effect == "lead_error"
        key, tag = ("pitch", "lead") if lead else ("harmonic", "ecc")
        period = _shape(fitted, key, effect)
        if period is None:
            raise OffsetEffectError(f"the diagnosis's {effect} has an infinite {key}")
        const = {"period_mm": period} if lead else {"harmonic": period}
        for phase in ("sin", "cos"):
            for a in slides if lead else turning:
                c = {"phase": phase, **const}
                out.append(Parameter(f"{a}.{tag}_{phase}", "periodic_error", a, constants=c))
    elif effect == "backlash":
        out = [Parameter(f"{a}.half_play", "backlash", a) for a in actuators]
    elif effect in ("thermal_growth", "zero_drift"):
        tau = _shape(fitted, "time_constant", effect)
        const: dict[str, Any] = {"clock": clock, "origin": float(origin)}
        if tau is not None:
            const["time_constant"] = tau
        kind, names = (
            ("thermal_growth", [(a, f"{a}.growth") for a in slides])
            if effect == "thermal_growth"
            else ("drift", [(a, f"{a}.drift_rate") for a in actuators])
        )
        out = [Parameter(n, kind, a, constants=const) for a, n in names]
    else:
        raise OffsetEffectError(f"'{effect}' is no offset kind (those: {OFFSET_EFFECTS})")
    return [p for p in out if p.name not in have]
