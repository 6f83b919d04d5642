"""Closure residuals and their Jacobians from MuJoCo site kinematics (one configuration).

For a closure between sites a and b the residual is ``p_a - p_b`` (connect) plus, for a
weld, the rotation vector of ``R_a R_b^T`` (world frame). Its Jacobian with respect to the
velocity coordinates is ``J_a - J_b`` (translation, rotation) from ``mj_jacSite``; for the
rotation part this is exact at a closed configuration, which is all Newton and the implicit
function theorem need.
"""

from __future__ import annotations

import mujoco
import numpy as np

from twin.mechanism import Mechanism
from twin.rotations import rotvec_from_matrix


def update_kinematics(mech: Mechanism, qpos: np.ndarray) -> None:
    """Positions, frames and the quantities ``mj_jac*`` needs, at ``qpos``."""
    mech.data.qpos[:] = qpos
    mujoco.mj_kinematics(mech.model, mech.data)
    mujoco.mj_comPos(mech.model, mech.data)


def closure_residual(mech: Mechanism) -> np.ndarray:
    """Stacked closure residual (metres, radians) at the current kinematics."""
    d = mech.data
    a, b = closure_sites(mech)
    dpos = d.site_xpos[a] - d.site_xpos[b]
    ra = d.site_xmat[a].reshape(-1, 3, 3)
    rb = d.site_xmat[b].reshape(-1, 3, 3)
    drot = rotvec_from_matrix(ra @ rb.transpose(0, 2, 1))
    return stack_closure_rows(mech, dpos[:, :, None], drot[:, :, None])[:, 0]


def site_jacobians(mech: Mechanism, sites: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translational and rotational site Jacobians, each (S, 3, nv)."""
    m, d = mech.model, mech.data
    jp = np.zeros((len(sites), 3, m.nv))
    jr = np.zeros((len(sites), 3, m.nv))
    for k, s in enumerate(sites):
        mujoco.mj_jacSite(m, d, jp[k], jr[k], int(s))
    return jp, jr


def closure_sites(mech: Mechanism) -> tuple[np.ndarray, np.ndarray]:
    """Site ids (a, b) of every closure, in closure order."""
    a = np.array([c.site_a for c in mech.closures], dtype=int)
    b = np.array([c.site_b for c in mech.closures], dtype=int)
    return a, b


def closure_jacobian(mech: Mechanism) -> np.ndarray:
    """d(residual)/d(velocity coordinates), (n_closure, nv)."""
    a, b = closure_sites(mech)
    jpa, jra = site_jacobians(mech, a)
    jpb, jrb = site_jacobians(mech, b)
    return stack_closure_rows(mech, jpa - jpb, jra - jrb)


def stack_closure_rows(mech: Mechanism, dpos: np.ndarray, drot: np.ndarray) -> np.ndarray:
    """Stack per-closure position rows (C,3,k) and rotation rows (C,3,k) in residual order."""
    out = np.empty((mech.n_closure, dpos.shape[-1]))
    row = 0
    for i, c in enumerate(mech.closures):
        out[row : row + 3] = dpos[i]
        if c.kind == "weld":
            out[row + 3 : row + 6] = drot[i]
        row += c.size
    return out
