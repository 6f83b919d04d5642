"""Physical effects a truth twin can carry beyond geometry, one per module.

Each effect is deterministic given its parameters and changes what the machine does with its
commands (the actuator side) or what the tracker reports (the reading side). Scenarios switch
them on in the truth; the calibration never sees them, only their consequences in readings.
"""

from twin.effects.backlash import Backlash
from twin.effects.base import ActuatorEffect, apply_actuator_effects
from twin.effects.gravity_compliance import GravityCompliance
from twin.effects.lead_error import LeadError
from twin.effects.thermal import ThermalGrowth

__all__ = [
    "ActuatorEffect",
    "Backlash",
    "GravityCompliance",
    "LeadError",
    "ThermalGrowth",
    "apply_actuator_effects",
]
