"""The diagnosis_benchmark study: A benchmark of the residual diagnosis, not an anecdote: many
random truths, one effect each.
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = ["aggregate", "kinds", "report", "study"]
