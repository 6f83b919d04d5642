"""Recalibration with an effect: nonlinear least squares over geometry and effect coefficients.

The model is the full nonlinear one: targets = F(x, c + D(c, t) theta), the forward
kinematics of the nominal mechanism with the geometric parameters x injected, at the joint
values the effect's correction gives (calib.loop.effect). Levenberg-Marquardt adjusts the
chosen geometric columns of x and every coefficient theta together; the Jacobian is
[dF/dx, dF/dq D] with dF/dq the actuator sensitivities of the current geometry at the
current joint values. The regressor D depends on the commands and their order only (or on
the starting geometry, for gravity loads), so it is evaluated once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.diagnosis.context import actuator_offsets
from calib.estimators.levenberg_marquardt import (
    JacobianFn,
    LMOptions,
    ResidualFn,
    levenberg_marquardt,
)
from calib.fit.model import CalibrationModel, ColumnJacobian
from calib.loop.effect import ActuatorCorrection
from twin.exceptions import ClosureError

# Gauss-Newton polish after Levenberg-Marquardt: stop once a step moves every parameter by at
# most this fraction of its standard error (see gauss_newton_polish)
POLISH_TOL_STD = 1e-8
POLISH_MAX_STEPS = 10
POLISH_RISE = 1e-8  # a relative rise of the cost beyond its evaluation noise stops the polish


@dataclass(frozen=True)
class LoopFit:
    values: np.ndarray  # every geometric parameter (SI); those not in ``columns`` as given
    correction: ActuatorCorrection  # with the fitted coefficients
    columns: np.ndarray  # geometric parameters adjusted
    residual_rms_3d_m: float  # RMS over readings of the 3D residual per target reading
    iterations: int
    converged: bool
    std_errors: np.ndarray  # (len(columns) + k,) SI, from the residual and the SVD of J
    polish_steps: int = 0  # Gauss-Newton steps after Levenberg-Marquardt


def residual_rms_3d(measured: np.ndarray, predicted: np.ndarray) -> float:
    """RMS over readings (pose, target) of the 3D distance measured - predicted, metres."""
    d = np.linalg.norm(np.asarray(measured) - np.asarray(predicted), axis=-1)
    return float(np.sqrt(np.mean(d**2)))


def fit_with_effect(
    model: CalibrationModel,
    values: np.ndarray,
    columns: np.ndarray,
    correction: ActuatorCorrection,
    commands: np.ndarray,
    order: np.ndarray,
    measured: np.ndarray,
    options: LMOptions | None = None,
) -> LoopFit:
    """Fit geometry ``columns`` (starting at ``values``) and the correction's coefficients
    (starting at ``correction.theta``) to ``measured`` targets (N, T, 3) at ``commands``."""
    commands = np.asarray(commands, dtype=float)
    cols = np.asarray(columns, dtype=int)
    base = np.array(values, dtype=float)
    d = correction.regressor(commands, np.asarray(order))  # (N, A, k)
    k = d.shape[2]
    n_geo = len(cols)

    def split(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = base.copy()
        x[cols] = z[:n_geo]
        return x, z[n_geo:]

    def joints(theta: np.ndarray) -> np.ndarray:
        return commands + (np.einsum("nak,k->na", d, theta) if k else 0.0)

    def residual(z: np.ndarray):
        x, theta = split(z)
        q = joints(theta)
        pred = model.predict(x, q)
        return (measured - pred.targets).reshape(-1), (x, pred)

    # the geometry's columns and the actuators' (offsets of their joints) in one pass
    columns_and_actuators = ColumnJacobian.of(model, cols, actuator_offsets(model) if k else None)

    def jacobian(z: np.ndarray, state) -> np.ndarray:
        x, pred = state
        jac = columns_and_actuators(x, pred)
        if not k:
            return -jac
        j_geo, j_act = jac[:, :n_geo], jac[:, n_geo:].reshape(len(commands), -1, d.shape[1])
        j_eff = np.einsum("nra,nak->nrk", j_act, d).reshape(-1, k)  # j_act (N, T*3, A)
        return -np.hstack([j_geo, j_eff])

    z0 = np.concatenate([base[cols], correction.theta])
    opt = options or LMOptions(max_iterations=30)
    res = levenberg_marquardt(residual, jacobian, z0, opt, (ClosureError,))
    z, r, jac, polish = res.x, res.residual, res.jacobian, 0
    if res.converged:  # only near a minimum are full Gauss-Newton steps safe
        z, r, jac, polish = gauss_newton_polish(residual, jacobian, z, r, jac)
    x, theta = split(z)
    r3 = r.reshape(measured.shape)
    return LoopFit(
        values=x,
        correction=correction.with_theta(theta),
        columns=cols,
        residual_rms_3d_m=residual_rms_3d(r3, np.zeros_like(r3)),
        iterations=res.iterations,
        converged=res.converged,
        std_errors=std_errors(r, jac),
        polish_steps=polish,
    )


def std_errors(residual: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """Standard errors of a least-squares fit: sqrt(diag(s^2 (J^T J)^-1)), s^2 = |r|^2 / dof.

    From the SVD of the column-scaled Jacobian, never from J^T J itself: the loop's Jacobian
    has a condition number of some 4e6 after column scaling, so forming J^T J (1e13) would
    leave the standard errors with some 1e-3 relative round-off."""
    r = np.asarray(residual, dtype=float)
    jac = np.asarray(jacobian, dtype=float)
    scale = np.linalg.norm(jac, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    _, sv, vt = np.linalg.svd(jac / scale, full_matrices=False)
    keep = sv > sv[0] * max(jac.shape) * np.finfo(float).eps if sv.size else sv > 0
    dof = max(r.size - jac.shape[1], 1)
    sigma2 = float(r @ r) / dof
    var = (vt[keep].T ** 2) @ (1.0 / sv[keep] ** 2)
    return np.sqrt(sigma2 * var) / scale


def gauss_newton_polish(
    residual: ResidualFn,
    jacobian: JacobianFn,
    z: np.ndarray,
    r: np.ndarray,
    jac: np.ndarray,
    tol_std: float = POLISH_TOL_STD,
    max_steps: int = POLISH_MAX_STEPS,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Full Gauss-Newton steps from Levenberg-Marquardt's end point ``z`` (residual ``r``,
    Jacobian ``jac`` there) until a step moves no parameter by more than ``tol_std`` of its
    standard error. Returns the point, its residual and Jacobian, and the number of steps.

    Levenberg-Marquardt stops once the Gauss-Newton step predicts a relative cost decrease
    below 1e-10, which, at the loop's noise floor, leaves it up to ~1e-4 standard errors from
    the minimum, wherever its path ended: a start changed by 1e-12 relative (one BLAS thread
    or two) moved the effect's coefficients by up to 3e-7 relative. The steps contract by
    some 18x each, so the end point is the minimum to ~1e-10 standard errors, whatever the
    start. A step that fails to evaluate (no closure) or raises the cost by more than its
    evaluation noise (``POLISH_RISE``, relative; the closure solves' round-off moves the loop's
    cost by some 5e-12 relative between steps) ends the polish at the last point: the start
    was too far from the minimum for full steps."""
    for step_no in range(1, max_steps + 1):
        scale = np.linalg.norm(jac, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        step = -np.linalg.lstsq(jac / scale, r, rcond=None)[0] / scale
        try:
            r_new, state = residual(z + step)
        except ClosureError:
            return z, r, jac, step_no - 1
        if not np.all(np.isfinite(r_new)) or r_new @ r_new > (r @ r) * (1.0 + POLISH_RISE):
            return z, r, jac, step_no - 1
        small = np.all(np.abs(step) <= tol_std * std_errors(r, jac))
        z = z + step
        r, jac = r_new, jacobian(z, state)
        if small:
            return z, r, jac, step_no
    return z, r, jac, max_steps
