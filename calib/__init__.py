"""What a user runs on readings, seeing only the nominal model: data/ -> fit/ (identify, verdict)
-> diagnosis/ -> loop/ -> compensate/; analysis/, estimators/ and two_step/ beside; cli/ the
commands (pkm-calib, or python -m calib)."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "exceptions": ("CalibError", "IdentifiabilityError"),
    },
)
