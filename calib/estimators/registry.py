"""Estimators by name, for scenario files: "ols", "liu", "liu_paper", "liu_cv", "ridge", "pcr"."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from calib.estimators.linear import Estimator
from calib.estimators.liu import Liu
from calib.estimators.liu_cv import LiuCV
from calib.estimators.liu_paper_units import LiuPaperUnits
from calib.estimators.ols import OLS
from calib.estimators.pcr import PCR
from calib.estimators.ridge import Ridge

ESTIMATORS: dict[str, Callable[..., Estimator]] = {
    "ols": OLS,
    "liu": Liu,
    "liu_paper": LiuPaperUnits,  # needs is_angle (calib.two_step.fine passes it)
    "liu_cv": LiuCV,  # k and d by cross-validation over the calibration poses
    "ridge": Ridge,
    "pcr": PCR,
}


def make_estimator(name: str, **options: Any) -> Estimator:
    """A new estimator by name; ``options`` go to its constructor."""
    if name not in ESTIMATORS:
        raise ValueError(f"unknown estimator '{name}'; known: {sorted(ESTIMATORS)}")
    try:
        return ESTIMATORS[name](**options)
    except TypeError as exc:
        raise ValueError(f"bad options {sorted(options)} for estimator '{name}': {exc}") from exc
