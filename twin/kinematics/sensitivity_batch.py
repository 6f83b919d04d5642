"""The identification Jacobian of many poses at once (twin.kinematics.sensitivity, vectorised).

Same mathematics as :func:`twin.kinematics.sensitivity.target_jacobian` and
:func:`twin.kinematics.sensitivity.tool_twist_jacobian` (screws of the parameters, the
implicit-function theorem over the closures), computed for all poses together: the frames
from the numpy kinematic tree (twin.kinematics.tree), the screws as arrays over poses and
parameters, and the implicit term ``-J_t (dc/dq)^-1 dc/dpi`` through one adjoint solve per
output coordinate (twin.kinematics.adjoint), contracted only over the (site, parameter)
pairs that move. The tests hold it equal to the per-pose function to round-off.

Where the compiled kernel covers the machine (a serial chain or a square closure system),
the same steps run pose by pose in machine code instead (twin.kinematics.sensitivity_compiled); the
arrays over poses here serve over-determined closures and are the kernel's reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.kinematics.adjoint import adjoint_solve
from twin.kinematics.compiled import compiled_plan, kernels_pay
from twin.kinematics.reduced import ClosureStructure, cross_soa
from twin.kinematics.sensitivity_compiled import jacobian_compiled
from twin.kinematics.structure import (
    KinematicStructure,
    fast_kinematics,
    kinematic_structure,
    one_blas_thread,
)
from twin.kinematics.tree import TreeFrames, dofs_moving_sites, tree_frames
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet, require_geometry

COMPILED = (
    True  # the compiled kernel (twin.kinematics.sensitivity_compiled) where it covers the machine
)
CHUNK = 256  # poses per pass: bounds the (poses x sites x parameters) arrays


@dataclass(frozen=True)
class JacobianPlan:
    """What depends only on the machine's structure: reused for every parameter value."""

    structure: KinematicStructure
    free: np.ndarray
    target_moves: np.ndarray  # (T, n_free): the free dof moves the target
    tool_moves: np.ndarray  # (1, n_free): the free dof moves the tool site

    @classmethod
    def for_mechanism(cls, mech: Mechanism) -> JacobianPlan:
        free = mech.free_dofs()
        return cls(
            structure=kinematic_structure(mech),
            free=free,
            target_moves=dofs_moving_sites(mech.model, mech.target_sites, free),
            tool_moves=dofs_moving_sites(mech.model, [mech.tool_site], free),
        )


@dataclass(frozen=True)
class Outputs:
    """The sites whose motion is differentiated: their positions (3 rows each, x, y, z)
    and, with ``angular``, their rotations as well (3 more rows each, angular velocity)."""

    sites: np.ndarray  # (O,) site ids
    moves: np.ndarray  # (O, n_free): the free dof moves the site
    angular: bool

    @property
    def rows(self) -> int:
        return 6 if self.angular else 3


def frames_at(model, qpos: np.ndarray) -> dict[str, np.ndarray]:
    """Body, joint and site frames (leading pose axis, MuJoCo's field names and shapes) at
    configurations ``qpos`` (N, nq), from the numpy kinematic tree."""
    from twin.kinematics.tree import TreePlan

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


def _chunk(
    mech: Mechanism, params: ParameterSet, values: np.ndarray, qpos: np.ndarray, out: Outputs
) -> np.ndarray:
    """(N, O*rows, n) for the configurations ``qpos`` (N, nq): rows site-major, x, y, z of
    the position, then (``out.angular``) of the rotation.

    A parameter's screw moves a site it affects by ``t + w x (p - o)`` (translation ``t``,
    rotation ``w`` about the pivot ``o``), i.e. ``v + w x p`` with ``v = t - w x o``, and
    turns it by ``w``; the closures' rows are the differences of their two sites' motions
    (and of ``w`` for a weld's rotation). The implicit term ``-z^T c_pi`` (``z`` from the
    adjoint solve, one column per output row) is contracted without forming ``c_pi``
    (:func:`_implicit_term`)."""
    m = mech.model
    fk = fast_kinematics(mech)
    frames = tree_frames(fk.tree, m, np.ascontiguousarray(qpos.T), fk.numbers())
    cs = fk.closure
    closure_sites = cs.sites if cs is not None else np.zeros(0, dtype=int)
    sites = np.concatenate([closure_sites, out.sites]).astype(int)
    t, wn, o = params.screws_soa(m, frames.xpos, frames.xmat, frames.xanchor, frames.xaxis, values)
    vn = t - cross_soa(wn, o)  # (3, n, N)
    site_pos = frames.site_positions(m, sites)  # (3, S, N)
    affected = params.site_affected(m, sites).astype(float)  # (S, n)
    n_pose, n_par, nc, n_o = len(qpos), len(params), len(closure_sites) // 2, len(out.sites)
    d = out.rows
    pt = site_pos[:, 2 * nc :]  # (3, O, N)
    ts, ks = np.nonzero(affected[2 * nc :])  # (output site, parameter) pairs that move
    y = np.zeros((n_o, d, n_par, n_pose))
    if ts.size:
        y[ts, :3, ks] = (vn[:, ks] + cross_soa(wn[:, ks], pt[:, ts])).transpose(1, 0, 2)
        if out.angular:
            y[ts, 3:, ks] = wn[:, ks].transpose(1, 0, 2)
    y = y.transpose(3, 0, 1, 2).reshape(n_pose, n_o * d, n_par)
    if cs is None:  # a serial chain: the explicit term is all
        return y
    axes, anchors = cs.dof_axes(frames)  # (3, n_free, N)
    n_free = axes.shape[1]
    rot = cs.dof_rot
    motion = np.zeros((d, n_o, n_free, n_pose))  # output rows moved by each free dof
    motion[:3] = axes[:, None]
    motion[:3, :, rot] = cross_soa(axes[:, None, rot], pt[:, :, None] - anchors[:, None, rot])
    if out.angular:  # a rotational dof turns the site about its axis, a translation not
        motion[3:, :, rot] = axes[:, None, rot]
    motion *= out.moves[None, :, :, None]
    jt = motion.transpose(2, 1, 0, 3).reshape(n_free, n_o * d, n_pose)  # (n_free, m, N)
    if not cs.square:
        aff_a, aff_b = affected[:nc], affected[nc : 2 * nc]
        pa, pb = site_pos[:, :nc], site_pos[:, nc : 2 * nc]  # (3, C, N)
        # least squares over more closure equations than free dofs: dq = -J^+ c_pi
        c_pi = np.zeros((mech.n_closure, n_par, n_pose))
        da = (vn[:, None] + cross_soa(wn[:, None], pa[:, :, None])) * aff_a[None, :, :, None]
        db = (vn[:, None] + cross_soa(wn[:, None], pb[:, :, None])) * aff_b[None, :, :, None]
        dw = wn[:, None] * (aff_a - aff_b)[None, :, :, None]
        for i, c in enumerate(mech.closures):
            r0 = cs.row_offset[i]
            c_pi[r0 : r0 + 3] = da[:, i] - db[:, i]
            if c.kind == "weld":
                c_pi[r0 + 3 : r0 + 6] = dw[:, i]
        dq = cs.solve(cs.matrices(frames, site_pos[:, : 2 * nc], -c_pi))  # (n_free, n, N)
        return np.einsum("fmn,fkn->nmk", jt, dq) + y
    # jt dq = -jt J^-1 c_pi = -(J^-T jt^T)^T c_pi: one adjoint solve with a right-hand
    # side per output row and pose instead of one with a column per parameter
    z = adjoint_solve(cs, frames, site_pos[:, : 2 * nc], jt)  # (n_closure, m, N)
    return y - _implicit_term(cs, z, vn, wn, site_pos[:, : 2 * nc], affected[: 2 * nc])


def _implicit_term(
    cs: ClosureStructure,
    z: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    site_pos: np.ndarray,
    affected: np.ndarray,
) -> np.ndarray:
    """``z^T c_pi`` (N, m, n) without forming ``c_pi``: only the (closure site, parameter)
    pairs that move contribute, ``+-z_c . (v + w x p)`` (the site's velocity under the
    parameter's screw; + for a closure's first site, - for its second) and ``+-z_rot . w``
    for a weld's rotation rows. ``z`` (n_closure, m, N), ``v``/``w`` (3, n, N),
    ``site_pos`` (3, 2C, N), ``affected`` (2C, n)."""
    nc = site_pos.shape[1] // 2
    n_par, n_rhs, n_pose = v.shape[1], z.shape[1], z.shape[2]
    site, k = np.nonzero(affected)  # the pairs that move, grouped by site
    u = v[:, k] + cross_soa(w[:, k], site_pos[:, site])  # (3, P, N)
    contrib = np.empty((len(k), n_rhs, n_pose))
    for s in np.unique(site):
        pairs = np.flatnonzero(site == s)
        c = s % nc
        r0 = cs.row_offset[c]
        rows = 6 if cs.weld[c] else 3  # a weld's rotation rows pair with w
        twist = np.concatenate([u[:, pairs], w[:, k[pairs]]])[:rows]  # (rows, p, N)
        acc = np.einsum("imn,ipn->pmn", z[r0 : r0 + rows], twist)
        contrib[pairs] = acc if s < nc else -acc
    out = np.zeros((n_par, n_rhs, n_pose))
    if np.unique(k).size == k.size:  # each parameter moves one closure site (the hexapod)
        out[k] = contrib
    else:
        np.add.at(out, k, contrib)
    return out.transpose(2, 1, 0)


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
    out = Outputs(np.asarray(mech.target_sites, dtype=int), plan.target_moves, angular=False)
    return _batched(mech, params, values, qpos, out).reshape(-1, len(params))


def tool_twist_jacobian_batch(
    mech: Mechanism,
    params: ParameterSet,
    values: np.ndarray,
    qpos: np.ndarray,
    plan: JacobianPlan | None = None,
) -> np.ndarray:
    """d(tool pose error twist)/d(parameters) at closed configurations ``qpos`` (N, nq):
    (N, 6, n), the linear velocity of the tool point then the angular velocity, world axes
    (:func:`twin.kinematics.sensitivity.tool_twist_jacobian` of every pose). ``mech`` carries the
    model
    with ``values`` injected; ``plan`` (from the nominal machine) may be reused."""
    plan = plan or JacobianPlan.for_mechanism(mech)
    out = Outputs(np.array([mech.tool_site], dtype=int), plan.tool_moves, angular=True)
    return _batched(mech, params, values, qpos, out)


def _batched(
    mech: Mechanism, params: ParameterSet, values: np.ndarray, qpos: np.ndarray, out: Outputs
) -> np.ndarray:
    """:func:`_chunk` over ``qpos`` (N, nq) in chunks of CHUNK poses: (N, O*rows, n)."""
    require_geometry(params, "the identification Jacobian (twin.kinematics.sensitivity_batch)")
    qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
    if not len(qpos):
        return np.zeros((0, len(out.sites) * out.rows, len(params)))
    fk = fast_kinematics(mech)
    plan = compiled_plan(fk) if COMPILED and kernels_pay(fk, len(qpos)) else None
    if plan is not None and (fk.closure is None or fk.closure.square):  # pose by pose
        return jacobian_compiled(fk, plan, params, values, qpos, out.sites, out.moves, out.angular)
    with one_blas_thread():
        parts = [
            _chunk(mech, params, values, qpos[i : i + CHUNK], out)
            for i in range(0, len(qpos), CHUNK)
        ]
    return np.concatenate(parts)
