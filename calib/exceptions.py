"""Errors a user can cause in calibration, each naming its cause."""

from __future__ import annotations

from calib.data.dataset import DatasetError


class CalibError(Exception):
    """Base class of calibration errors other than dataset errors."""


class IdentifiabilityError(CalibError):
    """The pose set cannot identify the requested parameters (rank deficiency)."""


class ConvergenceError(CalibError):
    """An estimator did not converge."""


class TooManyOutliersError(CalibError):
    """Robust identification rejected more readings than a few gross outliers would explain."""


__all__ = [
    "CalibError",
    "ConvergenceError",
    "DatasetError",
    "IdentifiabilityError",
    "TooManyOutliersError",
]
