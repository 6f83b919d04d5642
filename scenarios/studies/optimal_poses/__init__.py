"""The optimal_poses study: Measurement design on the hexapod: the second paper's optimal poses
against random ones.
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = ["report", "study"]
