"""The error-model kinds that offset an actuator's joint value: their constants and units.

Each is one scalar ``v`` of one actuator (element: the actuator's name) that adds
``v * phi`` to the joint value its command asks, ``phi`` a function of the command ``c`` (SI)
and of the state of the machine at the reading (the calibration model computes it:
calib.fit.kinds):

* ``periodic_error``: ``phi = sin`` or ``cos`` (constant ``phase``) of ``2 pi c / period``
  for a prismatic actuator (constant ``period_mm``: a screw's lead error at its pitch) or of
  ``harmonic * c`` for a revolute one (constant ``harmonic``: an encoder's or a gear's
  eccentricity, once or n times per revolution). A function of the commands alone.
* ``backlash``: ``phi = -s``, ``s`` (+1 / -1) the direction of the actuator's last motion
  before the reading: the joint stops short of its command by the half-backlash ``v``.
* ``drift``: ``phi = h(t - origin)``, a zero drifting in time.
* ``thermal_growth``: ``phi = h(t - origin) c``, a strain of the actuator's travel growing in
  time (a screw or a leg warming up).
* ``thermal_expansion``: ``phi = (T - origin) c``, the strain of the travel at the
  temperature ``T`` (deg C) of the reading; ``origin`` the temperature of the nominal model.

``h(t) = tau (1 - exp(-t / tau))`` for the constant ``time_constant`` tau, ``h(t) = t``
without one (linear): unit initial rate, so ``v`` is the initial rate whatever tau. ``t``
runs on the constant ``clock``: ``time_s`` (the dataset's seconds) or ``order`` (its
measurement order, one unit per pose); ``time_constant`` and ``origin`` are in its unit.

Values: metres or radians for ``periodic_error`` and ``backlash`` (files mm, deg); per clock
unit for ``drift`` (mm/s, deg/pose, ...); strain per clock unit for ``thermal_growth`` (ppm/s,
ppm/pose) and per kelvin for ``thermal_expansion`` (ppm/K).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from twin.exceptions import ParameterError

OFFSET_KINDS = ("periodic_error", "backlash", "drift", "thermal_growth", "thermal_expansion")
TIME_KINDS = ("drift", "thermal_growth")
CLOCKS = ("time_s", "order")
CONSTANTS = ("phase", "period_mm", "harmonic", "time_constant", "clock", "origin")
PHASES = ("sin", "cos")
_ALLOWED = {
    "periodic_error": ("phase", "period_mm", "harmonic"),
    "backlash": (),
    "drift": ("time_constant", "clock", "origin"),
    "thermal_growth": ("time_constant", "clock", "origin"),
    "thermal_expansion": ("origin",),
}
STRAIN_FACTOR = 1e6  # ppm per unit strain


def _positive(name: str, key: str, value: Any) -> None:
    if (
        isinstance(value, (bool, np.bool_))
        or not isinstance(value, (int, float, np.number))
        or not math.isfinite(float(value))
        or float(value) <= 0
    ):
        raise ParameterError(
            f"parameter '{name}': {key} must be a finite number > 0, got {value!r}"
        )


def check_constants(name: str, kind: str, constants: dict[str, Any]) -> None:
    """The constants of a parameter (``period_mm``, ``phase``, ...) are its kind's and valid."""
    allowed = _ALLOWED.get(kind, ())
    wrong = [k for k in constants if k not in allowed]
    if wrong:
        owner = [k for k, v in _ALLOWED.items() if wrong[0] in v]
        raise ParameterError(
            f"parameter '{name}': {wrong[0]} belongs to a {' or '.join(owner) or 'no kind'}, "
            f"not to a {kind}"
        )
    if kind == "periodic_error":
        if constants.get("phase") not in PHASES:
            raise ParameterError(
                f"parameter '{name}': a periodic_error needs phase 'sin' or 'cos', got "
                f"{constants.get('phase')!r}"
            )
        shapes = [k for k in ("period_mm", "harmonic") if k in constants]
        if len(shapes) != 1:
            raise ParameterError(
                f"parameter '{name}': a periodic_error needs one of period_mm (a prismatic "
                f"actuator) or harmonic (a revolute one), got {shapes or 'neither'}"
            )
        _positive(name, shapes[0], constants[shapes[0]])
    if kind in TIME_KINDS:
        if constants.get("clock") not in CLOCKS:
            raise ParameterError(
                f"parameter '{name}': a {kind} needs clock 'time_s' (the dataset's seconds) or "
                f"'order' (its measurement order), got {constants.get('clock')!r}"
            )
        if "time_constant" in constants:
            _positive(name, "time_constant", constants["time_constant"])
    if "origin" in constants:
        v = constants["origin"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ParameterError(f"parameter '{name}': origin must be a finite number, got {v!r}")


def check_joint(name: str, kind: str, constants: dict[str, Any], turns: bool) -> None:
    """A periodic error's period suits its joint: ``period_mm`` a prismatic one's,
    ``harmonic`` a revolute one's."""
    if kind != "periodic_error":
        return
    want = "harmonic" if turns else "period_mm"
    if want not in constants:
        joint = "revolute" if turns else "prismatic"
        raise ParameterError(
            f"parameter '{name}': its actuator is {joint}, so its periodic_error takes {want}"
        )


def needed_column(kind: str, constants: dict[str, Any]) -> str | None:
    """The dataset column the kind reads at each reading (None: the commands alone)."""
    if kind == "backlash":
        return "direction"
    if kind in TIME_KINDS:
        return str(constants["clock"])
    if kind == "thermal_expansion":
        return "temperature_c"
    return None


def _clock_unit(constants: dict[str, Any]) -> str:
    return "s" if constants.get("clock") == "time_s" else "pose"


def offset_units(kind: str, turns: bool, constants: dict[str, Any], si: bool) -> str:
    """The unit of one offset parameter, in SI (``si``) or in files."""
    length = ("rad" if turns else "m") if si else ("deg" if turns else "mm")
    if kind in ("periodic_error", "backlash"):
        return length
    if kind == "drift":
        return f"{length}/{_clock_unit(constants)}"
    strain = "1" if si else "ppm"
    if kind == "thermal_growth":
        return f"{strain}/{_clock_unit(constants)}"
    return f"{strain}/K"


def offset_factor(kind: str, turns: bool) -> float:
    """Value in files per SI value of one offset parameter."""
    if kind in ("thermal_growth", "thermal_expansion"):
        return STRAIN_FACTOR
    return float(np.degrees(1.0)) if turns else 1e3


def offset_range(kind: str, turns: bool, constants: dict[str, Any]) -> float:
    """The size (SI) an offset parameter can have on a built machine, as the prior and the
    redundancy analysis compare sizes: 0.1 mm or 1 mrad of joint offset, over an hour
    (3600 s or 100 poses) for the time kinds, a strain of 1e-4 (100 ppm, a steel screw
    warmer by 9 K) for the strains."""
    span = 3600.0 if constants.get("clock") == "time_s" else 100.0
    length = 1e-3 if turns else 1e-4
    return {
        "periodic_error": length,
        "backlash": length,
        "drift": length / span,
        "thermal_growth": 1e-4 / span,
        "thermal_expansion": 1e-4 / 10.0,
    }[kind]
