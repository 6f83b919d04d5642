"""The undeclared_effect study: Close the loop: the truth carries effects nobody declared; the
diagnosis finds them.
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = ["report", "study"]
