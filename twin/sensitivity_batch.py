"""The identification Jacobian of many poses at once (twin.sensitivity, vectorised).

Same mathematics as :func:`twin.sensitivity.target_jacobian` (screws of the parameters, the
implicit-function theorem over the closures), computed for all poses together: the frames
from the numpy kinematic tree (twin.kinematics_tree), the screws and site derivatives as
arrays over poses and parameters, and ``dq/dpi = -(dc/dq)^-1 dc/dpi`` for every parameter at
once by the per-closure elimination of twin.kinematics_reduced (one elimination, one column
per parameter). The tests hold it equal to the per-pose function to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.kinematics_adjoint import adjoint_solve
from twin.kinematics_fast import (
    KinematicStructure,
    fast_kinematics,
    kinematic_structure,
    one_blas_thread,
)
from twin.kinematics_reduced import cross_soa
from twin.kinematics_tree import TreeFrames, tree_frames
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet

CHUNK = 256  # poses per pass: bounds the (poses x sites x parameters) arrays


@dataclass(frozen=True)
class JacobianPlan:
    """What depends only on the machine's structure: reused for every parameter value."""

    structure: KinematicStructure
    free: np.ndarray
    target_moves: np.ndarray  # (T, n_free): the free dof moves the target

    @classmethod
    def for_mechanism(cls, mech: Mechanism) -> JacobianPlan:
        st = kinematic_structure(mech)
        free = mech.free_dofs()
        moves = np.zeros((mech.n_targets, len(free)), dtype=bool)
        parent = mech.model.body_parentid
        for i, s in enumerate(mech.target_sites):
            b, chain = int(mech.model.site_bodyid[s]), set()
            while True:
                chain.add(b)
                if b == 0:
                    break
                b = int(parent[b])
            moves[i] = np.isin(mech.model.dof_bodyid[free], list(chain))
        return cls(structure=st, free=free, target_moves=moves)


def frames_at(model, qpos: np.ndarray) -> dict[str, np.ndarray]:
    """Body, joint and site frames (leading pose axis, MuJoCo's field names and shapes) at
    configurations ``qpos`` (N, nq), from the numpy kinematic tree."""
    from twin.kinematics_tree import TreePlan

    frames = tree_frames(TreePlan(model), model, np.ascontiguousarray(np.atleast_2d(qpos).T))
    return _aos(model, frames, np.arange(model.nsite))


def _aos(model, frames: TreeFrames, sites: np.ndarray) -> dict[str, np.ndarray]:
    """MuJoCo-shaped frame arrays (pose axis first) of ``frames``; sites not in ``sites`` 0."""
    n = frames.xpos.shape[-1]
    site_xpos = np.zeros((n, model.nsite, 3))
    site_xpos[:, sites] = frames.site_positions(model, sites).transpose(2, 1, 0)
    site_xmat = np.zeros((n, model.nsite, 9))
    site_xmat[:, sites] = (
        frames.site_rotations(model, sites).transpose(3, 2, 0, 1).reshape(n, len(sites), 9)
    )
    return {
        "xpos": frames.xpos.transpose(2, 1, 0),
        "xmat": frames.xmat.transpose(3, 2, 0, 1).reshape(n, -1, 9),
        "xaxis": frames.xaxis.transpose(2, 1, 0),
        "xanchor": frames.xanchor.transpose(2, 1, 0),
        "site_xpos": site_xpos,
        "site_xmat": site_xmat,
    }


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
    fk = fast_kinematics(mech)
    frames = tree_frames(fk.tree, m, np.ascontiguousarray(qpos.T), fk.numbers())
    cs = fk.closure
    targets = mech.target_sites
    closure_sites = cs.sites if cs is not None else np.zeros(0, dtype=int)
    sites = np.concatenate([closure_sites, targets]).astype(int)
    aos = _aos(m, frames, sites)
    screws = params.screws_batch(m, aos, values)
    dp, dw = params.site_derivatives_batch(m, aos["site_xpos"], sites, screws)
    n_pose, n_par, nc = len(qpos), len(params), len(closure_sites) // 2
    y = dp[:, 2 * nc :].reshape(n_pose, -1, n_par)
    if cs is None:  # a serial chain: the explicit term is all
        return y
    c_pi = _closure_rows(mech, dp[:, :nc] - dp[:, nc : 2 * nc], dw[:, :nc] - dw[:, nc : 2 * nc])
    site_pos = aos["site_xpos"][:, sites].transpose(2, 1, 0)  # (3, S, N)
    axes, anchors = cs.dof_axes(frames)  # (3, n_free, N)
    pt = site_pos[:, 2 * nc :]  # (3, T, N)
    lin = np.broadcast_to(axes[:, None], (3, len(targets), *axes.shape[1:])).copy()
    rot = cs.dof_rot
    lever = pt[:, :, None] - anchors[:, None, rot]
    lin[:, :, rot] = cross_soa(axes[:, None, rot], lever)
    lin *= plan.target_moves[None, :, :, None]
    jt = lin.transpose(3, 1, 0, 2).reshape(n_pose, -1, len(plan.free))  # (N, T*3, n_free)
    if cs.square:
        # jt dq = -jt J^-1 c_pi = -(J^-T jt^T)^T c_pi: one adjoint solve with T*3 right-hand
        # sides per pose instead of one with a column per parameter
        z = adjoint_solve(cs, frames, site_pos[:, : 2 * nc], jt.transpose(2, 1, 0))
        return y - z.transpose(2, 1, 0) @ c_pi
    mats = cs.matrices(frames, site_pos[:, : 2 * nc], -c_pi.transpose(1, 2, 0))
    dq = cs.solve(mats)  # (n_free, n_par, N), least squares
    return jt @ dq.transpose(2, 0, 1) + y


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
    with one_blas_thread():
        parts = [
            _chunk(mech, params, values, qpos[i : i + CHUNK], plan)
            for i in range(0, len(qpos), CHUNK)
        ]
    return np.concatenate(parts).reshape(-1, len(params))
