"""Identification Jacobian of the tracker targets with respect to geometric parameters.

Neither MuJoCo nor pinocchio differentiates with respect to geometry, so the derivative is
built from the parameters' screws (twin.parameters) and the implicit-function theorem over
the closed chain: with the actuators held, the closure c(q, pi) = 0 defines q(pi), and

    dq/dpi = -(dc/dq)^+ dc/dpi,      dy/dpi = (dy/dq) dq/dpi + (dy/dpi)_explicit

for the target positions y. A serial chain has no closure and no free dof: the implicit part
vanishes and dy/dpi is the explicit term alone. Tests compare it with finite differences of
the full solve. twin.kinematics.sensitivity_batch computes the same for many poses at once.
"""

from __future__ import annotations

import numpy as np

from twin.kinematics.closure import (
    closure_jacobian,
    closure_sites,
    site_jacobians,
    stack_closure_rows,
    update_kinematics,
)
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet, require_geometry


def _implicit(
    mech: Mechanism, params: ParameterSet, values: np.ndarray, qpos: np.ndarray, sites: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """dq_free/dpi and the explicit site derivatives (dp, dw) of ``sites``, at ``qpos``."""
    require_geometry(params, "the identification Jacobian (twin.kinematics.sensitivity)")
    update_kinematics(mech, qpos)
    a, b = closure_sites(mech)
    all_sites = np.concatenate([a, b, sites])
    screws = params.screws(mech.model, mech.data, values)
    dp, dw = params.site_derivatives(mech.model, mech.data, values, all_sites, screws)
    nc = len(a)
    c_pi = stack_closure_rows(mech, dp[:nc] - dp[nc : 2 * nc], dw[:nc] - dw[nc : 2 * nc])
    free = mech.free_dofs()
    if free.size == 0:  # a serial chain, or closures that leave nothing free
        return np.zeros((0, len(params))), free, dp[2 * nc :], dw[2 * nc :]
    c_q = closure_jacobian(mech)[:, free]
    if c_q.shape[0] == c_q.shape[1]:
        dq = np.linalg.solve(c_q, -c_pi)
    else:
        dq = np.linalg.lstsq(c_q, -c_pi, rcond=None)[0]
    return dq, free, dp[2 * nc :], dw[2 * nc :]


def target_jacobian(
    mech: Mechanism, params: ParameterSet, values: np.ndarray, qpos: np.ndarray
) -> np.ndarray:
    """d(target positions)/d(parameters), (T*3, n), at a closed configuration ``qpos``.

    ``mech`` must carry the model with ``values`` injected; rows are target-major
    (target 0 x, y, z, target 1 x, ...), matching ``targets.reshape(-1)``.
    """
    dq, free, dp, _ = _implicit(mech, params, values, qpos, mech.target_sites)
    jp, _ = site_jacobians(mech, mech.target_sites)
    y_q = jp[:, :, free].reshape(3 * len(mech.target_sites), len(free))
    return y_q @ dq + dp.reshape(-1, len(params))


def tool_twist_jacobian(
    mech: Mechanism, params: ParameterSet, values: np.ndarray, qpos: np.ndarray
) -> np.ndarray:
    """d(tool pose error twist)/d(parameters), (6, n): linear velocity of the tool point and
    angular velocity, world axes (the first paper's B of Eq. 7, from the twin). For many
    poses, twin.kinematics.sensitivity_batch.tool_twist_jacobian_batch (the tests' reference is
    this)."""
    sites = np.array([mech.tool_site])
    dq, free, dp, dw = _implicit(mech, params, values, qpos, sites)
    jp, jr = site_jacobians(mech, sites)
    lin = jp[0][:, free] @ dq + dp[0]
    ang = jr[0][:, free] @ dq + dw[0]
    return np.vstack([lin, ang])
