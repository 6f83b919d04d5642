"""Coarse calibration (first paper, section 4.3, Eq. 15): encoder offsets alone, by OLS, iterated.

Each round commands the plan's poses with the current encoder settings, measures the targets,
regresses their deviation from the nominal positions on H_xi (the encoder columns of H at the
current settings), and updates the settings; the structural errors act as disturbance. The
loop stops when the update is below ``rel_tol`` of the estimate (the paper's 5 %).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from calib.estimators.ols import OLS
from calib.exceptions import ConvergenceError
from calib.fit.model import CalibrationModel
from calib.two_step.nominal import nominal_targets
from twin.workspace import commands_for_poses

Measure = Callable[[np.ndarray], np.ndarray]  # commands (N, A) -> measured targets (N, T, 3)


@dataclass(frozen=True)
class CoarseResult:
    values: np.ndarray  # full parameter vector (SI): encoder offsets set, the rest zero
    iterations: int
    converged: bool
    relative_changes: list[float] = field(default_factory=list)
    rms_deviation_mm: list[float] = field(default_factory=list)  # before each update


def coarse_calibration(
    model: CalibrationModel,
    encoder_mask: np.ndarray,
    poses: np.ndarray,
    measure: Measure,
    rel_tol: float = 0.05,
    max_iterations: int = 10,
) -> CoarseResult:
    """Estimate the encoder offsets (``encoder_mask`` columns) from measurements at ``poses``."""
    values = np.zeros(model.n_parameters)
    idx = np.flatnonzero(encoder_mask)
    if idx.size == 0:
        raise ConvergenceError("coarse calibration needs at least one encoder-offset parameter")
    changes, rms = [], []
    for it in range(1, max_iterations + 1):
        mech = model.mechanism(values)
        commands = commands_for_poses(mech, poses)
        measured = measure(commands)
        dev = (measured - nominal_targets(mech, poses)).reshape(-1)
        rms.append(float(np.sqrt(np.mean(dev**2)) * 1e3))
        pred = model.predict(values, commands)
        h_xi = model.jacobian(values, pred)[:, idx]
        step = OLS().fit(h_xi, dev).x
        values[idx] += step
        change = float(np.linalg.norm(step) / max(np.linalg.norm(values[idx]), 1e-300))
        changes.append(change)
        if change <= rel_tol:
            return CoarseResult(values, it, True, changes, rms)
    return CoarseResult(values, max_iterations, False, changes, rms)
