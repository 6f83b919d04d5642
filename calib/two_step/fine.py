"""Fine calibration (first paper, sections 4.1-4.2): the identifiable errors by a linear estimator.

At the coarse settings, the plan's poses are commanded and measured; the deviation of the
targets from their nominal positions is regressed on the reconstructed H (Steps 1-3) by each
estimator asked for (OLS, Liu, ridge, PCR).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.analysis.reconstruction import correlation_reconstruction
from calib.estimators.linear import LinearEstimate
from calib.estimators.registry import make_estimator
from calib.exceptions import IdentifiabilityError
from calib.fit.model import CalibrationModel
from calib.two_step.coarse import Measure
from calib.two_step.nominal import nominal_targets


@dataclass(frozen=True)
class FineProblem:
    """The linear regression of Eq. (10) at the coarse settings."""

    h: np.ndarray  # (n_eq, m) reconstructed identification Jacobian
    dp: np.ndarray  # (n_eq,) measured minus nominal target positions
    columns: np.ndarray  # indices of the kept parameters in the full vector
    base_values: np.ndarray  # the coarse settings (full vector)
    is_angle: np.ndarray | None = None  # per kept column: an angle (for paper-unit estimators)


def fine_problem(
    model: CalibrationModel,
    base_values: np.ndarray,
    encoder_mask: np.ndarray,
    poses: np.ndarray,
    measure: Measure,
) -> FineProblem:
    commands = model.commands_for_poses(base_values, poses)  # configurations kept
    mech = model.mechanism(base_values)
    measured = measure(commands)
    dp = (measured - nominal_targets(mech, poses)).reshape(-1)
    h_full = model.jacobian(base_values, model.predict(base_values, commands))
    kept = np.array(sorted(correlation_reconstruction(h_full, model.params.names, encoder_mask)))
    if kept.size <= int(np.sum(encoder_mask)):
        raise IdentifiabilityError(
            f"the plan ({len(poses)} poses) identifies only the {kept.size} encoder offsets and "
            "no structural error: fine calibration needs nodes spread over more than one line "
            "(the first paper uses two layers of 7 x 7 nodes)"
        )
    return FineProblem(
        h_full[:, kept],
        dp,
        kept,
        np.array(base_values, dtype=float),
        np.asarray(model.params.is_angle)[kept],
    )


def estimate(problem: FineProblem, method: str, **options) -> tuple[LinearEstimate, np.ndarray]:
    """One estimator's estimate and the full parameter vector it implies."""
    if method == "liu_paper":  # the paper's units: which columns are angles
        options = {"is_angle": problem.is_angle, **options}
    est = make_estimator(method, **options).fit(problem.h, problem.dp)
    values = problem.base_values.copy()
    values[problem.columns] += est.x
    return est, values
