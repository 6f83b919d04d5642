"""The diagnosis benchmark's effect kinds: which names are right for each, how each is sized.

:data:`ACCEPTED` maps each twin effect kind to the diagnosis's candidate names that are a
right answer for it (and why); :data:`SCALED` says which argument scales its magnitude;
:func:`effect_for` builds the twin effect at a value, :func:`not_applicable` says why a kind
does not apply to a machine, :func:`is_correct` scores a named effect.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from scenarios.machine_setup import EFFECTS
from twin.mechanism import Mechanism

# Which diagnosis names are a right answer for each twin kind, and why. "none" is right only
# where the twin's effect is (nearly) one the geometric error model itself absorbs.
ACCEPTED: dict[str, tuple[str, ...]] = {
    # the screw's periodic travel error at its pitch: the free-pitch "lead_error" candidate
    "lead_error": ("lead_error",),
    # the same screw error with a 2nd harmonic: its 1st harmonic is still "lead_error"
    "lead_error_harmonic": ("lead_error",),
    # legs growing in time: a command-proportional growth in time ("thermal_growth"); on a
    # hexapod whose legs have similar lengths, an offset drift in time ("zero_drift") is
    # nearly the same shape, so both name the physics right (heat makes the machine drift);
    # links growing in time: the structure expanding in time ("thermal_expansion")
    "thermal_warmup": ("thermal_growth", "zero_drift", "thermal_expansion"),
    "thermal_growth": ("thermal_growth", "zero_drift", "thermal_expansion"),
    # a scale error of each actuator's measuring system
    "actuator_gain": ("gain_error",),
    # each reflector off its nominal site in the tool frame
    "reflector_offset": ("reflector_offsets",),
    # lost motion on reversal, at the actuator (backlash) or in a revolute drive
    "backlash": ("backlash",),
    "joint_backlash": ("backlash",),
    # deflection under the machine's own weight and a payload
    "gravity_compliance": ("gravity_compliance",),
    "joint_compliance": ("gravity_compliance",),
    # an eccentric encoder disc read by one head (every harmonic, mostly once per revolution)
    "encoder_eccentricity": ("encoder_eccentricity",),
    # a wrong air compensation is a scale of every distance from the head: "tracker_scale";
    # with a short tracker distance most of it is a scale of the base frame that geometry
    # absorbs, so "none" is an acceptable answer too
    "tracker_air_temperature": ("tracker_scale", "none"),
    "none": ("none",),
}

# How each kind is sized: (argument, reference value, fixed arguments, "linear" or
# "inverse"). The argument is scaled linearly from the reference value so the effect's
# noise-free RMS on the readings hits the target ("inverse": the argument is a stiffness,
# the effect scales with its inverse, the compliance).
SCALED: dict[str, tuple[str, float, dict[str, Any], str]] = {
    "lead_error": ("amplitude_m", 5e-6, {"pitch_m": 5e-3}, "linear"),
    # amplitudes [a, 0.4 a] of the once- and twice-per-revolution harmonics: a scales both
    "lead_error_harmonic": ("amplitude_m", 10e-6, {"pitch_m": 4e-3}, "linear"),
    "thermal_warmup": (
        "delta_K",
        3.0,
        # the long members of each benchmark machine warm: the hexapod's legs, the polisher's
        # limbs, the arm's upper arm and forearm (not its base and column: not a uniform scale)
        {"tau_s": 1200.0, "seconds_per_pose": 30.0, "bodies": "leg*,limb*,link3*,link4*"},
        "linear",
    ),
    "thermal_growth": ("rate_K_per_pose", 0.02, {}, "linear"),
    "actuator_gain": ("magnitude_ppm", 200.0, {}, "linear"),
    "reflector_offset": ("magnitude_m", 30e-6, {}, "linear"),
    "backlash": ("play_m", 10e-6, {}, "linear"),
    "joint_backlash": ("play_rad", 30 * np.pi / 648000, {}, "linear"),
    # stiffness of prismatic (2e7 N/m) and revolute (2e5 N m/rad) drives, both / ratio
    "gravity_compliance": ("stiffness_N_per_m", 2e7, {}, "inverse"),
    "joint_compliance": ("stiffness_Nm_per_rad", 5e4, {"payload_kg": 5.0}, "inverse"),
    "encoder_eccentricity": ("eccentricity_m", 3e-6, {"radius_m": 0.03}, "linear"),
    # hall minus set temperature (K); the set temperature stays 20 C
    "tracker_air_temperature": ("hall_minus_set_K", 3.0, {}, "linear"),
}
SEEDED = ("lead_error_harmonic", "actuator_gain", "reflector_offset", "encoder_eccentricity")
# the twin's effects by kind, as the scenario files name them (scenarios.machine_setup.EFFECTS)
EFFECT_TYPES = dict(EFFECTS)


def effect_for(kind: str, value: float, seed: int, overrides: dict[str, Any] | None = None):
    """The twin effect ``kind`` with its scaled argument at ``value`` (``overrides``: fixed
    arguments a machine sets otherwise, e.g. which bodies warm up)."""
    arg, _, fixed, _ = SCALED[kind]
    args = {**fixed, **(overrides or {})}
    if kind == "lead_error_harmonic":
        args["amplitudes_m"] = (value, 0.4 * value)
    elif kind == "tracker_air_temperature":
        args.update(set_C=20.0, hall_C=20.0 + value)
    elif kind == "gravity_compliance":
        args.update(stiffness_N_per_m=value, stiffness_Nm_per_rad=value * 1e-2)
    else:
        args[arg] = value
    if kind in SEEDED:
        args["seed"] = seed
    return EFFECT_TYPES[kind](**args)


def not_applicable(kind: str, mech: Mechanism) -> str | None:
    """Why ``kind`` does not apply to this machine (None when it does)."""
    slide = np.asarray(mech.actuator_is_slide)
    if kind in ("joint_backlash", "joint_compliance", "encoder_eccentricity") and slide.all():
        return "acts on revolute actuators; this machine's actuators are all prismatic"
    if kind in ("lead_error", "lead_error_harmonic", "thermal_growth") and not slide.any():
        return "acts on prismatic (screw) actuators; this machine has none"
    if kind == "gravity_compliance" and mech.masses_defaulted:
        # (joint_compliance carries a tool payload, which loads even a model without masses)
        return "the model's masses are defaulted and no payload is set: nothing loads it"
    if kind == "reflector_offset" and mech.n_targets < 2:
        return "one reflector: its offset is the tool offset, which geometry absorbs"
    return None


def is_correct(kind: str, named: str) -> bool:
    """Every effect named is one :data:`ACCEPTED` allows for ``kind`` ("a+b" names two)."""
    parts = named.split("+")
    return all(p in ACCEPTED[kind] for p in parts)
