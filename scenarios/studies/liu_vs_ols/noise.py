"""What the tracker noise alone does to the fine estimate (first paper, Eqs. 17-18), and to
the test layer's pose error.

* The Monte Carlo of Eqs. 17-18: 10^4 draws of the tracker noise on one truth's geometry and
  one H, each estimator refitted per draw (its d and k re-estimated every time), the overall
  standard deviation of its parameters (mm and deg summed as the paper does) and
  eta = 1 - sigma_L / sigma_OLS.
* eta at the d actually used: each estimate is a linear map A of the measurements with its d
  and k fixed at the values of the experiment run, so its parameter spread under noise of
  standard deviation sigma is sigma sqrt(trace(S A A^T S)) (S: SI to mm or deg), no draws.
* The noise ceiling: the same draws' estimate minus its mean (for OLS exactly A e) moves the
  head at each test pose by the position part of the tool twist B delta; the mean (and the
  max) over the test poses of its length, averaged over the draws, is the pose error that
  the noise alone leaves. No shrinkage of the estimate can gain more than OLS's value of it.

eta compares parameter spreads, not pose errors: an estimate can scatter its parameters
less and still place the head no better (the spread it removes may lie along directions the
test poses do not see, and its bias moves the head too).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from calib.estimators import OLS, DrawEstimator, LinearEstimate, Liu, LiuPaperUnits, draws
from calib.two_step import nominal_targets
from twin.kinematics import forward_batch

MC_CHUNK = 2000  # Monte Carlo runs projected at once


@dataclass(frozen=True)
class NoiseStudy:
    spread: dict[str, float]  # overall standard deviation (Eq. 18), mm and deg summed
    test_mean_um: dict[str, float]  # noise-only test-layer mean position error, over draws
    test_max_um: dict[str, float]  # noise-only test-layer max position error, over draws

    def eta_percent(self, label: str) -> float:
        return (1.0 - self.spread[label] / self.spread["ols"]) * 100.0


def display_scale(params: Any, columns: np.ndarray) -> np.ndarray:
    """SI -> mm or deg per kept parameter."""
    shown = params.to_display(np.eye(len(params)))[np.ix_(columns, columns)]
    return np.diag(shown)


def monte_carlo(bench: Any, cal: Any, runs: int, test_position_jacobian: np.ndarray) -> NoiseStudy:
    """Eqs. 17-18 over ``runs`` noise draws on one truth and one H, and the pose error the
    noise alone leaves at the test poses (``test_position_jacobian``: (N, 3, m), the position
    part of d(tool twist)/d(kept parameters) at the test poses).

    As the paper's simulation (section 5): the targets of the truth's geometry at the fine
    plan (its effects left out: the simulation studies the measurement disturbance alone),
    plus draws of the tracker noise."""
    params, problem = bench.machine.params, cal.problem
    coarse_mech = bench.model.mechanism(cal.coarse.values)
    clean = forward_batch(bench.machine.truth, cal.fine_commands).targets
    dp_clean = (clean - nominal_targets(coarse_mech, cal.fine_poses)).reshape(-1)
    noise = bench.rng.normal(0.0, bench.sigma_m, size=(runs, dp_clean.size))
    scale = display_scale(params, problem.columns)
    estimators: dict[str, DrawEstimator] = {
        "ols": OLS(),
        "liu": Liu(),
        "liu_k1": Liu(k=1.0),
        "liu_paper_deg": LiuPaperUnits(angle_unit="deg", is_angle=problem.is_angle),
        "liu_paper_rad": LiuPaperUnits(angle_unit="rad", is_angle=problem.is_angle),
    }
    # each run's estimate is its own; what the estimators share of a run (its products with
    # the singular vectors of H, its OLS residual) is computed once, MC_CHUNK runs at a time
    shared = draws(problem.h, dp_clean, noise, MC_CHUNK)
    spread, mean_um, max_um = {}, {}, {}
    b = np.asarray(test_position_jacobian, dtype=float)
    for label, est in estimators.items():
        x = est.fit_draws(shared)  # (runs, m) SI
        spread[label] = float(np.sqrt(np.sum((x * scale).var(axis=0, ddof=1))))
        moved = np.linalg.norm(np.einsum("pim,rm->rpi", b, x - x.mean(axis=0)), axis=-1)
        mean_um[label] = float(moved.mean(axis=1).mean()) * 1e6
        max_um[label] = float(moved.max(axis=1).mean()) * 1e6
    return NoiseStudy(spread, mean_um, max_um)


def spread_at_used(est: LinearEstimate, scale: np.ndarray, sigma_m: float) -> float | None:
    """Overall standard deviation (Eq. 18, mm and deg summed) of the estimate's linear map
    with its d and k fixed at the values used, for tracker noise ``sigma_m`` per coordinate."""
    if est.linear_map is None:
        return None
    a = est.linear_map * scale[:, None]
    return float(sigma_m * np.sqrt(np.sum(a * a)))


def eta_at_used(
    estimates: dict[str, tuple[LinearEstimate, Any]], scale: np.ndarray, sigma_m: float
) -> dict[str, float]:
    """eta (Eq. 17, %) of every estimate against OLS with d and k as the experiment run
    chose them (analytic: no draws)."""
    if "ols" not in estimates:
        return {}
    ols = spread_at_used(estimates["ols"][0], scale, sigma_m)
    out = {}
    for label, (est, _) in estimates.items():
        s = spread_at_used(est, scale, sigma_m)
        if label != "ols" and s is not None and ols:
            out[label] = (1.0 - s / ols) * 100.0
    return out
