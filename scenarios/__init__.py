"""Scenario runners: a scenario file (config) names a study (studies/) that wires truth twin ->
dataset -> calib -> compensate -> re-measure -> score and writes results/<name>/ (runner);
sweep/ runs it over seeds, recording/ logs it to rerun. python -m scenarios run|list|sweep."""

__all__: list[str] = []
