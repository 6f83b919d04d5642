"""The mechanism in software: a machine's MJCF as a Mechanism, its named parameters, the laser
tracker and the measurement of a truth twin; kinematics/, effects/ and formats/ below."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "mechanism": ("Mechanism",),
        "parameters": ("Parameter", "ParameterSet"),
        "tracker": ("Tracker",),
    },
)
