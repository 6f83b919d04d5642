"""Identification of geometric parameters from a Dataset (target residual, Levenberg-Marquardt).

The residual is measured minus predicted target position, for every pose and target (the
mean of the repeats), in the base frame. This is equivalent to the second paper's Eq. 5 (which
compares limb lengths recomputed from measured poses) but needs no pose fit, uses every
measured coordinate, and works for any machine the MJCF describes.

Robust by default: one *reading* is one pose x target (3 coordinates), judged by the norm of
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

More than ``max_rejected_fraction`` of the readings rejected is refused
(:class:`TooManyOutliersError`): that is a wrong model, not a few bad readings.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from calib.dataset import Dataset, DatasetError
from calib.estimators.levenberg_marquardt import (
    LMOptions,
    levenberg_marquardt,
    reweighted_levenberg_marquardt,
)
from calib.exceptions import IdentifiabilityError, TooManyOutliersError
from calib.identifiability import IdentifiabilityReport, analyse
from calib.model import CalibrationModel, Prediction
from twin.exceptions import ClosureError
from twin.mechanism import Mechanism

# each reweighting round starts near its minimum and need not reach it exactly: a few
# nearly Gauss-Newton steps (the final least-squares refit converges fully)
ROUND_OPTIONS = LMOptions(max_iterations=3, step_tol=1e-9, cost_rtol=1e-8, initial_damping=1e-6)
CHI2_3_MEDIAN_ROOT = float(np.sqrt(stats.chi2.ppf(0.5, 3)))  # median 3D norm / sigma, 1.538


@dataclass(frozen=True)
class Observations:
    """A dataset bound to a mechanism: SI commands (P, A) and measured targets (P, T, 3).

    ``pose_ids`` (the dataset's pose ids, as text) and ``target_names`` label the rows of
    ``commands`` and the targets of ``measured``, in that order; None when not known."""

    commands: np.ndarray
    measured: np.ndarray
    pose_ids: tuple[str, ...] | None = None
    target_names: tuple[str, ...] | None = None


def bind_dataset(mech: Mechanism, dataset: Dataset) -> Observations:
    """Check a dataset against the mechanism (model, names, units, frame) and order it like it."""
    if dataset.model != mech.name:
        raise DatasetError(
            f"dataset is for model '{dataset.model}', but the mechanism is '{mech.name}'"
        )
    if dataset.frame != "base":
        raise DatasetError(
            f"dataset frame is '{dataset.frame}'; calibration needs readings in the machine's "
            "base frame (register the tracker to the base first)"
        )
    dataset.check_against(mech.actuator_names, mech.target_names)
    ds = dataset.reordered(mech.actuator_names, mech.target_names)
    for name, unit, slide in zip(
        ds.actuator_names, ds.actuator_units, mech.actuator_is_slide, strict=True
    ):
        expected = "mm" if slide else "deg"
        if unit != expected:
            kind = "prismatic" if slide else "revolute"
            raise DatasetError(
                f"actuator '{name}' is {kind} in the model, so its unit must be '{expected}', "
                f"but the dataset declares '{unit}'"
            )
    return Observations(
        commands=np.array(ds.commands),
        measured=np.array(ds.measured),
        pose_ids=tuple(str(p) for p in ds.pose_ids.tolist()),
        target_names=tuple(ds.target_names),
    )


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


@dataclass(frozen=True)
class IdentificationResult:
    names: tuple[str, ...]
    values: np.ndarray  # SI, every parameter (the unestimated keep their start value)
    estimated: np.ndarray  # bool mask
    std_errors: np.ndarray  # SI, NaN where not estimated; from the kept readings
    covariance: np.ndarray  # over the estimated parameters; from the kept readings
    residual_rms: float  # metres, per coordinate, over the kept readings
    iterations: int  # Levenberg-Marquardt iterations, every stage included
    converged: bool  # of the final least-squares fit
    history: list[float]  # cost after each accepted step of the final least-squares fit
    report: IdentifiabilityReport  # of all readings, at the start values
    rejected: tuple[Rejection, ...] = ()  # gross outliers left out, by pose then target
    robust_scale_m: float = float("nan")  # per-coordinate robust noise scale s (metres)


def robust_scale(norms: np.ndarray, n_free: int) -> float:
    """Per-coordinate noise scale from 3D residual norms, robust to a minority of outliers."""
    m = 3 * norms.size
    dof_factor = np.sqrt(m / max(m - n_free, 1))
    return float(np.median(norms) / CHI2_3_MEDIAN_ROOT * dof_factor)


def _one_blas_thread() -> contextlib.AbstractContextManager:
    """Numpy's BLAS on one thread: the products here are small, threads only cost."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # not installed: run as numpy is configured
        return contextlib.nullcontext()
    return threadpool_limits(1)


def identify(
    model: CalibrationModel,
    obs: Observations,
    x0: np.ndarray | None = None,
    unidentifiable: str = "raise",
    options: LMOptions | None = None,
    robust: bool = True,
    robust_options: RobustOptions | None = None,
) -> IdentificationResult:
    """Estimate the parameters; ``unidentifiable`` is "raise" or "fix" (keep them at x0).

    ``robust`` (default) rejects gross outliers by the rule of the module docstring;
    ``robust=False`` is plain least squares over every reading."""
    if unidentifiable not in ("raise", "fix"):
        raise ValueError(f"unidentifiable must be 'raise' or 'fix', got {unidentifiable!r}")
    with _one_blas_thread():
        return _identify(model, obs, x0, unidentifiable, options, robust, robust_options)


def _robust_fit(residual, jacobian, x0, n_free: int, opt: RobustOptions):
    """The M-estimator: reweighted least squares, the loss's scale from the residual."""
    floor_scale = opt.floor_m / opt.threshold
    weight_of = LOSS_WEIGHTS[opt.loss]

    def weights(r: np.ndarray) -> np.ndarray:
        norms = np.linalg.norm(r.reshape(-1, 3), axis=1)
        c = opt.loss_scale * max(robust_scale(norms, n_free), floor_scale)
        return weight_of((norms / c) ** 2)

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


def _identify(model, obs, x0, unidentifiable, options, robust, robust_options):
    n = model.n_parameters
    x_start = np.zeros(n) if x0 is None else np.array(x0, dtype=float)
    commands, measured = obs.commands, obs.measured
    n_targets = measured.shape[1]
    first = model.predict(x_start, commands)
    jac0 = model.jacobian(x_start, first)
    report = analyse(jac0, model.params.names)
    if report.n_identifiable < n and unidentifiable == "raise":
        raise IdentifiabilityError(
            f"{len(commands)} poses cannot identify all {n} parameters:\n{report.summary()}"
        )
    mask = np.array([nm in report.identifiable for nm in model.params.names])
    free = np.flatnonzero(mask)

    def full(xf: np.ndarray) -> np.ndarray:
        x = x_start.copy()
        x[free] = xf
        return x

    def problem(rows: np.ndarray | None):
        """Residual and Jacobian of the rows ``rows`` (None: all) over the free parameters."""

        def residual(xf: np.ndarray) -> tuple[np.ndarray, Prediction]:
            pred = model.predict(full(xf), commands)
            r = (measured - pred.targets).reshape(-1)
            return (r if rows is None else r[rows]), pred

        def jacobian(xf: np.ndarray, pred: Prediction) -> np.ndarray:
            jac = -model.jacobian(full(xf), pred)[:, free]
            return jac if rows is None else jac[rows]

        return residual, jacobian

    residual, jacobian = problem(None)
    res = levenberg_marquardt(residual, jacobian, x_start[free], options, (ClosureError,))
    iterations = res.iterations
    scale = robust_scale(np.linalg.norm(res.residual.reshape(-1, 3), axis=1), len(free))
    rejected: tuple[Rejection, ...] = ()
    if robust:
        opt = robust_options or RobustOptions()
        rob = _robust_fit(residual, jacobian, res.x, len(free), opt)
        iterations += rob.iterations
        norms = np.linalg.norm(rob.residual.reshape(-1, 3), axis=1)
        scale = robust_scale(norms, len(free))
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
                "wrong target or pose, wrong units, a tracker not registered to the base "
                "frame, or an unmodelled effect larger than the noise"
            )
        if rejected:  # else the least-squares fit over every reading is the answer
            rows = np.repeat(~bad, 3)
            kept = analyse(jac0[rows], model.params.names)
            lost = [nm for nm in report.identifiable if nm not in kept.identifiable]
            if lost:
                raise IdentifiabilityError(
                    f"after rejecting {len(rejected)} outlying readings the kept ones cannot "
                    f"identify {lost}:\n{kept.summary()}"
                )
            residual, jacobian = problem(rows)
            base = options or LMOptions()
            near = replace(base, initial_damping=min(base.initial_damping, 1e-6))
            res = levenberg_marquardt(residual, jacobian, rob.fit.x, near, (ClosureError,))
            iterations += res.iterations
    m = res.residual.size
    dof = max(m - len(free), 1)
    sigma2 = 2.0 * res.cost / dof
    jtj = res.jacobian.T @ res.jacobian
    cov = sigma2 * np.linalg.pinv(jtj)
    std = np.full(n, np.nan)
    std[free] = np.sqrt(np.clip(np.diag(cov), 0, None))
    return IdentificationResult(
        names=model.params.names,
        values=full(res.x),
        estimated=mask,
        std_errors=std,
        covariance=cov,
        residual_rms=float(np.sqrt(2.0 * res.cost / m)),
        iterations=iterations,
        converged=res.converged,
        history=res.history,
        report=report,
        rejected=rejected,
        robust_scale_m=scale,
    )


def model_from_files(mjcf: str, params_file: str) -> CalibrationModel:
    """A calibration model from an MJCF file and an error-model TOML file."""
    from twin.parameter_file import load_parameter_set

    mech = Mechanism.from_xml(mjcf)
    return CalibrationModel(mech, load_parameter_set(params_file, mech.model))
