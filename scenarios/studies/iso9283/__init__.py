"""The iso9283 study: ISO 9283 pose accuracy and repeatability at the standard's five cube
poses, before and after a calibration, on the hexapod and the 6R arm.
Its scenario file (TOML) beside its run (study.py) and report."""

__all__ = ["report", "study"]
