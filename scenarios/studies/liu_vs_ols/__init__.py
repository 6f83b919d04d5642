"""The liu_vs_ols study: Coarse then fine calibration of the hybrid polisher, Liu against OLS
(first paper, 4-5).
Its scenario files (TOML) beside its run (study.py), report and figures."""

__all__ = [
    "draws",
    "draws_figures",
    "figures",
    "loop",
    "noise",
    "pipeline",
    "report",
    "sentences",
    "study",
]
