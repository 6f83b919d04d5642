"""The identification Jacobian of many poses at once (twin.sensitivity, vectorised).

Same mathematics as :func:`twin.sensitivity.target_jacobian` (screws of the parameters, the
implicit-function theorem over the closures), computed for all poses together: one batched
kinematics pass for the frames, the screws and site derivatives as arrays over poses and
parameters, the closure and target Jacobians from the dof axes, and one batched solve.
The tests hold it equal to the per-pose function to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco.batch import Batch

from twin.closure import closure_sites
from twin.dof_axes import DofAxes
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet

FRAME_FIELDS = ("xpos", "xmat", "xaxis", "xanchor", "site_xpos", "site_xmat")
CHUNK = 256  # poses per pass: bounds the (poses x sites x parameters) arrays


@dataclass(frozen=True)
class JacobianPlan:
    """What depends only on the machine's structure: reused for every parameter value."""

    free: np.ndarray
    closure_axes: DofAxes
    target_axes: DofAxes
    closure_a: np.ndarray
    closure_b: np.ndarray

    @classmethod
    def for_mechanism(cls, mech: Mechanism) -> JacobianPlan:
        a, b = closure_sites(mech)
        free = mech.free_dofs()
        return cls(
            free=free,
            closure_axes=DofAxes(mech.model, np.concatenate([a, b]), free),
            target_axes=DofAxes(mech.model, mech.target_sites, free),
            closure_a=a,
            closure_b=b,
        )


def frames_at(model: mujoco.MjModel, qpos: np.ndarray) -> dict[str, np.ndarray]:
    """Body, joint and site frames (leading pose axis) at configurations ``qpos`` (N, nq)."""
    n = len(qpos)
    batch = Batch(model, nsim=n, nthread=1)
    bound = {f: batch.bind(f) for f in ("qpos", *FRAME_FIELDS)}
    bound["qpos"][:] = qpos
    batch.forward(stage=mujoco.mjtStage.mjSTAGE_POS)
    return {f: np.array(bound[f]) for f in FRAME_FIELDS}


def _closure_rows(mech: Mechanism, dpos: np.ndarray, drot: np.ndarray) -> np.ndarray:
    """Per-closure position and rotation rows (N, C, 3, k) stacked in residual order."""
    out = np.empty((dpos.shape[0], mech.n_closure, dpos.shape[-1]))
    row = 0
    for i, c in enumerate(mech.closures):
        out[:, row : row + 3] = dpos[:, i]
        if c.kind == "weld":
            out[:, row + 3 : row + 6] = drot[:, i]
        row += c.size
    return out


def _chunk(
    mech: Mechanism, params: ParameterSet, values: np.ndarray, qpos: np.ndarray, plan
) -> np.ndarray:
    m = mech.model
    frames = frames_at(m, qpos)
    screws = params.screws_batch(m, frames, values)
    a, b, targets = plan.closure_a, plan.closure_b, mech.target_sites
    nc, n_pose, n_par = len(a), len(qpos), len(params)
    dp, dw = params.site_derivatives_batch(
        m, frames["site_xpos"], np.concatenate([a, b, targets]), screws
    )
    y = dp[:, 2 * nc :].reshape(n_pose, -1, n_par)
    if plan.free.size == 0:  # a serial chain: the explicit term is all
        return y
    c_pi = _closure_rows(mech, dp[:, :nc] - dp[:, nc : 2 * nc], dw[:, :nc] - dw[:, nc : 2 * nc])
    p_closure = frames["site_xpos"][:, np.concatenate([a, b])]
    c_q = plan.closure_axes.closure_jacobian(
        mech, frames["xaxis"], frames["xanchor"], frames["xmat"], p_closure, plan.free
    )
    if c_q.shape[1] == c_q.shape[2]:
        dq = np.linalg.solve(c_q, -c_pi)
    else:
        dq = np.linalg.pinv(c_q) @ -c_pi
    jt = plan.target_axes.site_jacobian(
        m,
        frames["xaxis"],
        frames["xanchor"],
        frames["xmat"],
        frames["site_xpos"][:, targets],
        plan.free,
    )
    return jt.reshape(n_pose, -1, len(plan.free)) @ dq + y


def target_jacobian_batch(
    mech: Mechanism,
    params: ParameterSet,
    values: np.ndarray,
    qpos: np.ndarray,
    plan: JacobianPlan | None = None,
) -> np.ndarray:
    """d(targets)/d(parameters) at closed configurations ``qpos`` (N, nq): (N*T*3, n), rows
    pose-major then target then x, y, z (as ``targets.reshape(-1)``). ``mech`` carries the
    model with ``values`` injected; ``plan`` (from the nominal machine) may be reused."""
    plan = plan or JacobianPlan.for_mechanism(mech)
    qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
    parts = [
        _chunk(mech, params, values, qpos[i : i + CHUNK], plan) for i in range(0, len(qpos), CHUNK)
    ]
    return np.concatenate(parts).reshape(-1, len(params))
