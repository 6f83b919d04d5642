"""Physical effects a truth twin can carry beyond geometry, one per module.

Each effect is deterministic given its parameters (random draws only from its ``seed``) and
acts where its physics acts (see :mod:`twin.effects.base`): on the joint values the machine
takes for its commands, on its geometry at each pose's time, on the reflectors, or on the
tracker. Scenarios switch them on in the truth; the calibration never sees them, only their
consequences in readings.
"""

from twin.effects.actuator_gain import ActuatorGain
from twin.effects.backlash import Backlash
from twin.effects.base import (
    ActuatorEffect,
    Effect,
    GeometryEffect,
    ReadingEffect,
    TargetEffect,
    apply_actuator_effects,
    check_effects,
    model_at,
    target_offsets,
    tracker_with,
)
from twin.effects.cross_coupling import CrossCoupling
from twin.effects.encoder_eccentricity import EncoderEccentricity
from twin.effects.gravity_compliance import GravityCompliance
from twin.effects.joint_backlash import JointBacklash
from twin.effects.joint_compliance import JointCompliance
from twin.effects.lead_error import LeadError
from twin.effects.lead_error_harmonic import LeadErrorHarmonic
from twin.effects.reflector_offset import ReflectorOffset
from twin.effects.thermal import ThermalGrowth
from twin.effects.thermal_warmup import ThermalWarmup
from twin.effects.tracker_air import TrackerAirTemperature
from twin.effects.zero_drift import ZeroDrift

__all__ = [
    "ActuatorEffect",
    "ActuatorGain",
    "Backlash",
    "CrossCoupling",
    "Effect",
    "EncoderEccentricity",
    "GeometryEffect",
    "GravityCompliance",
    "JointBacklash",
    "JointCompliance",
    "LeadError",
    "LeadErrorHarmonic",
    "ReadingEffect",
    "ReflectorOffset",
    "TargetEffect",
    "ThermalGrowth",
    "ThermalWarmup",
    "TrackerAirTemperature",
    "ZeroDrift",
    "apply_actuator_effects",
    "check_effects",
    "model_at",
    "target_offsets",
    "tracker_with",
]
