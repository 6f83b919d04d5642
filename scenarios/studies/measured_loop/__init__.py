"""The measured_loop study: The loop on a machine with real characteristics, through the commands a
user types.
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = ["report", "study"]
