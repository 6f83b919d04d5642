"""Identification of geometric parameters from a Dataset (target residual, Levenberg-Marquardt).

The residual is measured minus predicted target position, for every pose and target (the
mean of the repeats), in the base frame. This is equivalent to the second paper's Eq. 5 (which
compares limb lengths recomputed from measured poses) but needs no pose fit, uses every
measured coordinate, and works for any machine the MJCF describes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.dataset import Dataset, DatasetError
from calib.estimators.levenberg_marquardt import LMOptions, levenberg_marquardt
from calib.exceptions import IdentifiabilityError
from calib.identifiability import IdentifiabilityReport, analyse
from calib.model import CalibrationModel, Prediction
from twin.exceptions import ClosureError
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class Observations:
    """A dataset bound to a mechanism: SI commands (P, A) and measured targets (P, T, 3)."""

    commands: np.ndarray
    measured: np.ndarray


def bind_dataset(mech: Mechanism, dataset: Dataset) -> Observations:
    """Check a dataset against the mechanism (names, units, frame) and order it like it."""
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
    return Observations(commands=np.array(ds.commands), measured=np.array(ds.measured))


@dataclass(frozen=True)
class IdentificationResult:
    names: tuple[str, ...]
    values: np.ndarray  # SI, every parameter (the unestimated keep their start value)
    estimated: np.ndarray  # bool mask
    std_errors: np.ndarray  # SI, NaN where not estimated
    covariance: np.ndarray  # over the estimated parameters
    residual_rms: float  # metres, per coordinate
    iterations: int
    converged: bool
    history: list[float]
    report: IdentifiabilityReport


def identify(
    model: CalibrationModel,
    obs: Observations,
    x0: np.ndarray | None = None,
    unidentifiable: str = "raise",
    options: LMOptions | None = None,
) -> IdentificationResult:
    """Estimate the parameters; ``unidentifiable`` is "raise" or "fix" (keep them at x0)."""
    n = model.n_parameters
    x_start = np.zeros(n) if x0 is None else np.array(x0, dtype=float)
    commands, measured = obs.commands, obs.measured
    first = model.predict(x_start, commands)
    jac0 = model.jacobian(x_start, first)
    report = analyse(jac0, model.params.names)
    if report.n_identifiable < n and unidentifiable == "raise":
        raise IdentifiabilityError(
            f"{len(commands)} poses cannot identify all {n} parameters:\n{report.summary()}"
        )
    if unidentifiable not in ("raise", "fix"):
        raise ValueError(f"unidentifiable must be 'raise' or 'fix', got {unidentifiable!r}")
    mask = np.array([nm in report.identifiable for nm in model.params.names])
    free = np.flatnonzero(mask)

    def full(xf: np.ndarray) -> np.ndarray:
        x = x_start.copy()
        x[free] = xf
        return x

    def residual(xf: np.ndarray) -> tuple[np.ndarray, Prediction]:
        pred = model.predict(full(xf), commands)
        return (measured - pred.targets).reshape(-1), pred

    def jacobian(xf: np.ndarray, pred: Prediction) -> np.ndarray:
        return -model.jacobian(full(xf), pred)[:, free]

    res = levenberg_marquardt(
        residual, jacobian, x_start[free], options, recoverable=(ClosureError,)
    )
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
        iterations=res.iterations,
        converged=res.converged,
        history=res.history,
        report=report,
    )


def model_from_files(mjcf: str, params_file: str) -> CalibrationModel:
    """A calibration model from an MJCF file and an error-model TOML file."""
    from twin.parameter_file import load_parameter_set

    mech = Mechanism.from_xml(mjcf)
    return CalibrationModel(mech, load_parameter_set(params_file, mech.model))
