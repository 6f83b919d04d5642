"""Identification Jacobian of the tracker targets with respect to geometric parameters.

Neither MuJoCo nor pinocchio differentiates with respect to geometry, so the derivative is
built from the parameters' screws (twin.parameters) and the implicit-function theorem over
the closed chain: with the actuators held, the closure c(q, pi) = 0 defines q(pi), and

    dq/dpi = -(dc/dq)^+ dc/dpi,      dy/dpi = (dy/dq) dq/dpi + (dy/dpi)_explicit

for the target positions y. Tests compare it with finite differences of the full solve.
"""

from __future__ import annotations

import numpy as np

from twin.closure import (
    closure_jacobian,
    closure_sites,
    site_jacobians,
    stack_closure_rows,
    update_kinematics,
)
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet


def target_jacobian(
    mech: Mechanism, params: ParameterSet, values: np.ndarray, qpos: np.ndarray
) -> np.ndarray:
    """d(target positions)/d(parameters), (T*3, n), at a closed configuration ``qpos``.

    ``mech`` must carry the model with ``values`` injected; rows are target-major
    (target 0 x, y, z, target 1 x, ...), matching ``targets.reshape(-1)``.
    """
    update_kinematics(mech, qpos)
    a, b = closure_sites(mech)
    sites = np.concatenate([a, b, mech.target_sites])
    screws = params.screws(mech.model, mech.data, values)
    dp, dw = params.site_derivatives(mech.model, mech.data, values, sites, screws)
    nc = len(a)
    c_pi = stack_closure_rows(mech, dp[:nc] - dp[nc : 2 * nc], dw[:nc] - dw[nc : 2 * nc])
    free = mech.free_dofs()
    c_q = closure_jacobian(mech)[:, free]
    if c_q.shape[0] == c_q.shape[1]:
        dq = np.linalg.solve(c_q, -c_pi)
    else:
        dq = np.linalg.lstsq(c_q, -c_pi, rcond=None)[0]
    jp, _ = site_jacobians(mech, mech.target_sites)
    y_q = jp[:, :, free].reshape(-1, len(free))
    return y_q @ dq + dp[2 * nc :].reshape(-1, len(params))
