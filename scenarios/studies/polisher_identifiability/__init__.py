"""The polisher_identifiability study: Identifiability of the hybrid polisher's source errors under
the first paper's plan (4.1).
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = ["figures", "report", "study"]
