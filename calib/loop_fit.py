"""Recalibration with an effect: nonlinear least squares over geometry and effect coefficients.

The model is the full nonlinear one: targets = F(x, c + D(c, t) theta), the forward
kinematics of the nominal mechanism with the geometric parameters x injected, at the joint
values the effect's correction gives (calib.loop_effect). Levenberg-Marquardt adjusts the
chosen geometric columns of x and every coefficient theta together; the Jacobian is
[dF/dx, dF/dq D] with dF/dq the actuator sensitivities of the current geometry at the
current joint values. The regressor D depends on the commands and their order only (or on
the starting geometry, for gravity loads), so it is evaluated once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.diagnosis import actuator_jacobians
from calib.estimators.levenberg_marquardt import LMOptions, levenberg_marquardt
from calib.loop_effect import ActuatorCorrection
from calib.model import CalibrationModel
from twin.exceptions import ClosureError


@dataclass(frozen=True)
class LoopFit:
    values: np.ndarray  # every geometric parameter (SI); those not in ``columns`` as given
    correction: ActuatorCorrection  # with the fitted coefficients
    columns: np.ndarray  # geometric parameters adjusted
    residual_rms_3d_m: float  # RMS over readings of the 3D residual per target reading
    iterations: int
    converged: bool
    std_errors: np.ndarray  # (len(columns) + k,) SI, from the residual and J^T J


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

    def jacobian(z: np.ndarray, state) -> np.ndarray:
        x, pred = state
        j_geo = model.jacobian(x, pred)[:, cols]
        if not k:
            return -j_geo
        j_act = actuator_jacobians(model, x, pred.qpos)  # (N, T*3, A)
        j_eff = np.einsum("nra,nak->nrk", j_act, d).reshape(-1, k)
        return -np.hstack([j_geo, j_eff])

    z0 = np.concatenate([base[cols], correction.theta])
    opt = options or LMOptions(max_iterations=30)
    res = levenberg_marquardt(residual, jacobian, z0, opt, (ClosureError,))
    x, theta = split(res.x)
    n_res = res.residual.size
    dof = max(n_res - len(z0), 1)
    sigma2 = float(res.residual @ res.residual) / dof
    cov = sigma2 * np.linalg.pinv(res.jacobian.T @ res.jacobian)
    r3 = res.residual.reshape(measured.shape)
    return LoopFit(
        values=x,
        correction=correction.with_theta(theta),
        columns=cols,
        residual_rms_3d_m=residual_rms_3d(r3, np.zeros_like(r3)),
        iterations=res.iterations,
        converged=res.converged,
        std_errors=np.sqrt(np.clip(np.diag(cov), 0.0, None)),
    )
