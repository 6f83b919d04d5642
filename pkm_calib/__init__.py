"""The one command, ``pkm-calib``: the calibration commands (calib.cli), the model commands
(twin.formats) and, with the scenarios extra installed, the scenario runs (scenarios). It
sits above every other floor, and nothing imports it."""

from common.face import face

__all__, __getattr__, __dir__ = face(__name__, {"command": ("main",)})
