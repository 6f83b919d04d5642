"""The hexapod_paper study: The second paper's simulation study on the 6-RRRPRR hexapod (Han et al.
2019).
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = ["report", "study"]
