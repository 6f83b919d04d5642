"""Batched forward kinematics: the same Newton as twin.kinematics, many poses.

A serial chain (no free dof) needs no Newton: one kinematics pass per pose.

``mujoco.batch.Batch`` runs the kinematics and the site Jacobians of every pose on a thread
pool; the Newton steps are solved for all poses at once with numpy. Each pose is checked
against the same tolerance as the single-pose solve, and a pose that fails raises.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco.batch import Batch

from twin.closure import closure_sites
from twin.dof_axes import DofAxes
from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics import ACCEPT, MAX_ITER, MAX_STEP, TOLERANCE, check_commands
from twin.mechanism import Mechanism
from twin.rotations import quat_from_rotvec, quat_multiply, rotvec_from_matrix

FREE = int(mujoco.mjtJoint.mjJNT_FREE)
BALL = int(mujoco.mjtJoint.mjJNT_BALL)


@dataclass(frozen=True)
class BatchSolution:
    qpos: np.ndarray  # (N, nq)
    tool_rotation: np.ndarray  # (N, 3, 3)
    tool_position: np.ndarray  # (N, 3)
    targets: np.ndarray  # (N, T, 3)
    residual: np.ndarray  # (N,)
    iterations: int


def integrate_positions(model: mujoco.MjModel, qpos: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """Vectorised ``mj_integratePos`` with unit time step over rows of qpos (N, nq)."""
    out = qpos.copy()
    for j in range(model.njnt):
        qa, da = model.jnt_qposadr[j], model.jnt_dofadr[j]
        jt = int(model.jnt_type[j])
        if jt == FREE:
            out[:, qa : qa + 3] += dq[:, da : da + 3]
            quat = quat_multiply(out[:, qa + 3 : qa + 7], quat_from_rotvec(dq[:, da + 3 : da + 6]))
            out[:, qa + 3 : qa + 7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
        elif jt == BALL:
            quat = quat_multiply(out[:, qa : qa + 4], quat_from_rotvec(dq[:, da : da + 3]))
            out[:, qa : qa + 4] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
        else:
            out[:, qa] += dq[:, da]
    return out


def _residual(mech: Mechanism, xpos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    a, b = closure_sites(mech)
    dpos = xpos[:, a] - xpos[:, b]
    ra = xmat[:, a].reshape(len(xpos), -1, 3, 3)
    rb = xmat[:, b].reshape(len(xpos), -1, 3, 3)
    drot = rotvec_from_matrix(ra @ np.swapaxes(rb, -1, -2))
    rows = []
    for i, c in enumerate(mech.closures):
        rows.append(dpos[:, i])
        if c.kind == "weld":
            rows.append(drot[:, i])
    return np.concatenate(rows, axis=1)


def _jacobian(mech: Mechanism, axes: DofAxes, frames: dict, ids: np.ndarray) -> np.ndarray:
    a, b = closure_sites(mech)
    p = frames["site_xpos"][ids][:, np.concatenate([a, b])]
    return axes.closure_jacobian(
        mech,
        frames["xaxis"][ids],
        frames["xanchor"][ids],
        frames["xmat"][ids],
        p,
        mech.free_dofs(),
    )


FIELDS = ("site_xpos", "site_xmat", "xaxis", "xanchor", "xmat")
CHUNK = 512  # poses solved together: bounds the memory of the stacked Jacobians


def forward_batch(
    mech: Mechanism,
    commands: np.ndarray,
    nthread: int = 0,
    start: np.ndarray | None = None,
    check_stroke: bool = True,
) -> BatchSolution:
    """Forward kinematics for commands (N, A) (SI); raises ClosureError naming failed poses.

    ``start``: one configuration (nq,) or one per pose (N, nq), e.g. the previous solution
    when the same poses are solved again for slightly different parameters.
    """
    commands = np.atleast_2d(np.asarray(commands, dtype=float))
    if commands.shape[1:] != (mech.n_actuators,):
        raise WorkspaceError(
            f"expected {mech.n_actuators} actuator commands {mech.actuator_names} per pose, "
            f"got shape {commands.shape}"
        )
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    bad = ~np.all(np.isfinite(commands), axis=1)
    if check_stroke:
        bad |= np.any((commands < lo - 1e-12) | (commands > hi + 1e-12), axis=1)
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        try:
            check_commands(mech, commands[k], stroke=check_stroke)
        except Exception as exc:
            raise type(exc)(f"pose {k}: {exc}") from None
    n = len(commands)
    m = mech.model
    a, b = closure_sites(mech)
    q0 = np.asarray(mech.home_qpos if start is None else start, dtype=float)
    if q0.ndim == 2 and q0.shape != (n, m.nq):
        raise ClosureError(f"start must be ({m.nq},) or ({n}, {m.nq}), got {q0.shape}")
    qpos = np.array(np.broadcast_to(q0, (n, m.nq)))
    qpos[:, mech.actuator_qpos] = commands
    if mech.free_dofs().size == 0:
        return _direct(mech, qpos)
    residual = np.full(n, np.inf)
    shapes = {
        "site_xpos": (m.nsite, 3),
        "site_xmat": (m.nsite, 9),
        "xaxis": (m.njnt, 3),
        "xanchor": (m.njnt, 3),
        "xmat": (m.nbody, 9),
    }
    frames = {f: np.zeros((n, *shapes[f])) for f in ("site_xpos", "site_xmat")}
    chunks = [slice(i, min(n, i + CHUNK)) for i in range(0, n, CHUNK)]
    workers = max(1, min(len(chunks), nthread if nthread > 0 else (os.cpu_count() or 1)))

    def work(k: int) -> int:
        batch = Batch(m, nsim=min(n, CHUNK), nthread=1)
        bound = {f: batch.bind(f) for f in ("qpos", *FIELDS)}
        axes = DofAxes(m, np.concatenate([a, b]), mech.free_dofs())
        its = 0
        for sl in chunks[k::workers]:
            chunk = {f: frames[f][sl] for f in frames}
            its = max(its, _solve_chunk(mech, batch, bound, axes, qpos[sl], residual[sl], chunk))
        return its

    if workers == 1:
        iterations = work(0)
    else:
        with ThreadPoolExecutor(workers) as pool:
            iterations = max(pool.map(work, range(workers)))
    failed = np.flatnonzero(~(residual < ACCEPT))
    if failed.size:
        raise ClosureError(
            f"batched forward kinematics of '{mech.name}': {failed.size} of {n} poses did not "
            f"close (first: pose {failed[0]}, residual {residual[failed[0]]:.3g})"
        )
    tool = mech.tool_site
    return BatchSolution(
        qpos=qpos,
        tool_rotation=frames["site_xmat"][:, tool].reshape(n, 3, 3),
        tool_position=frames["site_xpos"][:, tool].copy(),
        targets=frames["site_xpos"][:, mech.target_sites].copy(),
        residual=residual,
        iterations=iterations,
    )


def _direct(mech: Mechanism, qpos: np.ndarray) -> BatchSolution:
    """Every joint commanded (a serial chain): one kinematics pass per pose, nothing to solve."""
    m, n = mech.model, len(qpos)
    tool_r, tool_p = np.zeros((n, 3, 3)), np.zeros((n, 3))
    targets = np.zeros((n, mech.n_targets, 3))
    for chunk in range(0, n, CHUNK):
        ids = np.arange(chunk, min(n, chunk + CHUNK))
        batch = Batch(m, nsim=len(ids), nthread=1)
        bound = {f: batch.bind(f) for f in ("qpos", "site_xpos", "site_xmat")}
        bound["qpos"][:] = qpos[ids]
        batch.forward(stage=mujoco.mjtStage.mjSTAGE_POS)
        tool_r[ids] = bound["site_xmat"][:, mech.tool_site].reshape(-1, 3, 3)
        tool_p[ids] = bound["site_xpos"][:, mech.tool_site]
        targets[ids] = bound["site_xpos"][:, mech.target_sites]
    return BatchSolution(qpos, tool_r, tool_p, targets, np.zeros(n), 0)


def _solve_chunk(
    mech: Mechanism,
    batch: Batch,
    bound: dict,
    axes: DofAxes,
    qpos: np.ndarray,
    residual: np.ndarray,
    frames: dict,
) -> int:
    """Newton on one chunk, in place on qpos, residual and the output frames (views)."""
    m = mech.model
    n = len(qpos)
    free = mech.free_dofs()
    active = np.arange(n)
    best = np.full(n, np.inf)
    stall = np.zeros(n, dtype=int)
    it = 0
    for it in range(MAX_ITER + 1):
        bound["qpos"][active] = qpos[active]
        batch.forward(ids=active, stage=mujoco.mjtStage.mjSTAGE_POS)
        r = _residual(mech, bound["site_xpos"][active], bound["site_xmat"][active])
        err = np.max(np.abs(r), axis=1)
        residual[active] = err
        stall[active] = np.where(err >= 0.5 * best[active], stall[active] + 1, 0)
        best[active] = np.minimum(best[active], err)
        done = (err < TOLERANCE) | ((stall[active] >= 3) & (best[active] < ACCEPT))
        done |= ~np.isfinite(err)
        keep = ~done
        if not np.any(keep) or it == MAX_ITER:
            break
        ids = active[keep]
        jac = _jacobian(mech, axes, bound, ids)
        rhs = -r[keep][:, :, None]
        if jac.shape[1] != jac.shape[2]:  # not square: least squares by normal equations
            rhs = np.swapaxes(jac, 1, 2) @ rhs
            jac = np.swapaxes(jac, 1, 2) @ jac
        step = np.linalg.solve(jac, rhs)[:, :, 0]
        norm = np.linalg.norm(step, axis=1, keepdims=True)
        step *= np.minimum(1.0, MAX_STEP / np.maximum(norm, 1e-300))
        dq = np.zeros((len(ids), m.nv))
        dq[:, free] = step
        qpos[ids] = integrate_positions(m, qpos[ids], dq)
        active = ids
    # a simulation left out of later calls keeps the frames of its last (converged) call
    for f in ("site_xpos", "site_xmat"):
        frames[f][:] = bound[f][:n]
    return it
