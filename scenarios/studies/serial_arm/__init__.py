"""The serial_arm study: A serial arm measured by a tracker standing in its own frame: exactly a
user's path.
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = ["loop", "report", "study"]
