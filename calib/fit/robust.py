"""Gross outliers (a broken beam, the wrong reflector): found, listed, left out.

One *reading* is one pose x target (3 coordinates), judged by the norm of
its 3D residual.

1. Ordinary least squares over every reading (the answer of ``robust=False``).
2. From there a Cauchy M-estimator (iteratively reweighted least squares, the weight of a
   reading ``1 / (1 + (|r_i| / c)^2)`` with ``c = loss_scale * s``, default 3 s, ``s``
   re-estimated from the residual every round, until no weight moves by more than 0.01).
   ``s``, the robust scale, is a per-coordinate noise estimate from the median of the
   readings' 3D residual norms: ``s = median |r_i| / sqrt(chi2_3.median) * sqrt(m / (m - p))``
   (for Gaussian noise of sigma per coordinate ``|r_i|^2 / sigma^2`` is chi-square with 3
   degrees of freedom, median 2.366; the last factor undoes the shrinking of residuals by a
   fit of ``p`` parameters to ``m`` coordinates).
3. Rejection: a reading whose residual at the robust estimate exceeds
   ``max(threshold * s, floor_m)`` (defaults 6 s and 1 um). A good reading with Gaussian
   noise exceeds 6 s with probability 7.6e-8 (over 1,000 readings, a one-in-10,000 event);
   the floor keeps the round-off of noise-free data from counting as outliers.
4. Nothing rejected: the least-squares fit of step 1 is the answer, unchanged. Otherwise an
   ordinary least-squares refit on the kept readings only, from the robust estimate, gives
   the parameters, their covariance, standard errors and residual RMS.

Screen (before step 2, :func:`suspect_outliers`): the M-estimator costs as much as the fit
itself, and on clean data it ends where step 1 did. So it runs only when step 1's residuals
leave room for a gross outlier: when some reading's *deleted residual* (its residual had the
fit left it out, to first order ``(I - H_ii)^-1 r_i`` with ``H_ii`` its 3 x 3 block of the
hat matrix, which unmasks an outlier a high-leverage pose has pulled the fit towards) exceeds
``screen`` times the rejection limit (default 0.8: a Gaussian reading passes 4.8 s with
probability 4e-5, so on clean data the robust stage almost never runs). A reading the screen
lets through lies well inside the limit at the least-squares fit, where nothing would be
rejected. ``screen=0`` runs the robust stage always.

More than ``max_rejected_fraction`` of the readings rejected is refused
(:class:`TooManyOutliersError`): that is a wrong model, not a few bad readings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.estimators.levenberg_marquardt import (
    LMOptions,
    ReweightedResult,
    reweighted_levenberg_marquardt,
)
from twin.exceptions import ClosureError

# each reweighting round starts near its minimum and need not reach it exactly: a few
# nearly Gauss-Newton steps (the final least-squares refit converges fully)
ROUND_OPTIONS = LMOptions(max_iterations=3, step_tol=1e-9, cost_rtol=1e-8, initial_damping=1e-6)
# sqrt of the median of chi-square with 3 degrees of freedom (scipy.stats.chi2.ppf(0.5, 3)
# = 2.365974), the median 3D norm of Gaussian noise in units of its per-coordinate sigma
CHI2_3_MEDIAN_ROOT = 1.5381722544550522


@dataclass(frozen=True)
class Rejection:
    """A reading left out as a gross outlier: ``obs.measured[pose_index, target_index]``."""

    pose_index: int  # into obs.commands / obs.measured
    target_index: int  # into obs.measured's targets (the mechanism's target order)
    residual_m: float  # norm of its 3D residual at the robust estimate


# IRLS weight rho'(z) of each loss, z = (|r| / c)^2 (scipy.optimize.least_squares' losses)
LOSS_WEIGHTS = {
    "soft_l1": lambda z: 1.0 / np.sqrt(1.0 + z),
    "huber": lambda z: np.minimum(1.0, 1.0 / np.sqrt(np.maximum(z, 1e-300))),
    "cauchy": lambda z: 1.0 / (1.0 + z),
}


@dataclass(frozen=True)
class RobustOptions:
    """The outlier rule (see the module docstring); scales in robust scales ``s``."""

    threshold: float = 6.0  # reject a reading whose 3D residual exceeds threshold * s ...
    floor_m: float = 1e-6  # ... and this floor (round-off of noise-free data is no outlier)
    loss: str = "cauchy"  # a key of LOSS_WEIGHTS
    loss_scale: float = 3.0  # the loss's scale c = loss_scale * s
    max_rejected_fraction: float = 0.2  # refuse when more readings than this are rejected
    max_rounds: int = 30  # of reweighting ...
    weight_tol: float = 1e-2  # ... until no reading's weight changes by more than this
    screen: float = 0.8  # robust stage only if a deleted residual exceeds screen x the limit


def robust_scale(norms: np.ndarray, n_free: int) -> float:
    """Per-coordinate noise scale from 3D residual norms, robust to a minority of outliers."""
    m = 3 * norms.size
    dof_factor = np.sqrt(m / max(m - n_free, 1))
    return float(np.median(norms) / CHI2_3_MEDIAN_ROOT * dof_factor)


def suspect_outliers(
    residual: np.ndarray,
    jacobian: np.ndarray,
    n_readings: int,
    n_free: int,
    opt: RobustOptions,
    jtj: np.ndarray | None = None,
) -> bool:
    """Whether a least-squares fit (its residual and Jacobian, readings' rows first) may hide
    a gross outlier: some reading's deleted residual exceeds ``opt.screen`` times the
    rejection limit (module docstring). A singular or non-finite case answers True.
    ``jtj``: ``jacobian.T @ jacobian`` when the caller has it."""
    if opt.screen <= 0:
        return True
    rows = 3 * n_readings
    r = residual[:rows].reshape(-1, 3)
    scale = robust_scale(np.linalg.norm(r, axis=1), n_free)
    limit = opt.screen * max(opt.threshold * scale, opt.floor_m)
    try:
        cov = np.linalg.inv(jacobian.T @ jacobian if jtj is None else jtj)
    except np.linalg.LinAlgError:
        return True
    j = jacobian[:rows]
    jc = (j @ cov).reshape(n_readings, 3, -1)
    hat = np.einsum("nip,njp->nij", jc, j.reshape(n_readings, 3, -1))  # blocks of H
    try:
        deleted = np.linalg.solve(np.eye(3) - hat, r[:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:
        return True
    norms = np.linalg.norm(deleted, axis=1)
    return not bool(np.all(np.isfinite(norms)) and np.all(norms <= limit))


def robust_fit(
    residual, jacobian, x0: np.ndarray, n_free: int, opt: RobustOptions, n_readings: int
) -> ReweightedResult:
    """The M-estimator: reweighted least squares, the loss's scale from the residual."""
    floor_scale = opt.floor_m / opt.threshold
    weight_of = LOSS_WEIGHTS[opt.loss]

    def weights(r: np.ndarray) -> np.ndarray:
        """One weight per reading; rows past the readings (a prior's) keep weight 1."""
        groups = np.linalg.norm(r.reshape(-1, 3), axis=1)
        norms = groups[:n_readings]
        c = opt.loss_scale * max(robust_scale(norms, n_free), floor_scale)
        w = np.ones(groups.size)
        w[:n_readings] = weight_of((norms / c) ** 2)
        return w

    return reweighted_levenberg_marquardt(
        residual,
        jacobian,
        x0,
        weights,
        group=3,
        options=ROUND_OPTIONS,
        recoverable=(ClosureError,),
        max_rounds=opt.max_rounds,
        weight_tol=opt.weight_tol,
    )


def rejections(
    norms: np.ndarray, n_free: int, n_targets: int, opt: RobustOptions
) -> tuple[np.ndarray, tuple[Rejection, ...], float]:
    """(bad mask per reading, the rejections, the robust scale) at a robust estimate whose
    readings have 3D residual norms ``norms``; refuses too many (TooManyOutliersError)."""
    from calib.exceptions import TooManyOutliersError

    scale = robust_scale(norms, n_free)
    limit = max(opt.threshold * scale, opt.floor_m)
    bad = norms > limit
    rejected = tuple(
        Rejection(int(i) // n_targets, int(i) % n_targets, float(norms[i]))
        for i in np.flatnonzero(bad)
    )
    if len(rejected) > opt.max_rejected_fraction * norms.size:
        raise TooManyOutliersError(
            f"{len(rejected)} of {norms.size} readings "
            f"({100 * len(rejected) / norms.size:.1f} %, more than "
            f"{100 * opt.max_rejected_fraction:g} %) lie more than {limit * 1e3:.4g} mm "
            f"({opt.threshold:g} x the robust scale {scale * 1e3:.4g} mm) from the "
            "robust fit: that is no longer a few bad readings. Likely causes: the "
            "wrong model or error model for this machine, readings assigned to the "
            "wrong target or pose, wrong units, a tracker frame the dataset does not "
            "declare, or an unmodelled effect larger than the noise"
        )
    return bad, rejected, scale
