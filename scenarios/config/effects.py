"""The twin's effects a scenario file can name, by kind."""

from __future__ import annotations

from twin.effects import (
    ActuatorGain,
    Backlash,
    EncoderEccentricity,
    GravityCompliance,
    JointBacklash,
    JointCompliance,
    LeadError,
    LeadErrorHarmonic,
    ReflectorOffset,
    ThermalGrowth,
    ThermalWarmup,
    TrackerAirTemperature,
)

# effects a scenario can switch on in the truth (``truth.effects``), by ``kind``; their
# constructor arguments are the keys of each entry (checked by name when the file is loaded)
EFFECTS = {
    "thermal_growth": ThermalGrowth,
    "backlash": Backlash,
    "lead_error": LeadError,
    "gravity_compliance": GravityCompliance,
    "thermal_warmup": ThermalWarmup,
    "lead_error_harmonic": LeadErrorHarmonic,
    "joint_backlash": JointBacklash,
    "joint_compliance": JointCompliance,
    "actuator_gain": ActuatorGain,
    "reflector_offset": ReflectorOffset,
    "tracker_air_temperature": TrackerAirTemperature,
    "encoder_eccentricity": EncoderEccentricity,
}
EFFECT_EXCLUDED_ARGS = ("name",)  # the effect's label in reports, not a physical argument
