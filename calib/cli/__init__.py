"""The command line for measured data: ``pkm-calib identify|verify|diagnose|compensate|
export`` (commands), each subcommand in its own module."""

from common.face import face

__all__, __getattr__, __dir__ = face(__name__, {"commands": ("build_parser", "main")})
