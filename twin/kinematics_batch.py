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


class _DofAxes:
    """Per-dof motion axes of a model, for Jacobians computed in numpy from frames."""

    def __init__(self, model: mujoco.MjModel, sites: np.ndarray, free: np.ndarray) -> None:
        nv = model.nv
        free_mask = np.zeros(nv, dtype=bool)
        free_mask[free] = True
        self.joint = model.dof_jntid.copy()
        self.body = model.dof_bodyid.copy()
        self.kind = np.zeros(nv, dtype=int)  # 0 axis from xaxis, 1 world unit, 2 body column
        self.column = np.zeros(nv, dtype=int)
        self.is_rot = np.zeros(nv, dtype=bool)
        for d in range(nv):
            j = self.joint[d]
            jt, k = int(model.jnt_type[j]), d - model.jnt_dofadr[j]
            if jt == FREE:
                self.kind[d], self.column[d], self.is_rot[d] = (
                    (1, k, False) if k < 3 else (2, k - 3, True)
                )
            elif jt == BALL:
                self.kind[d], self.column[d], self.is_rot[d] = 2, k, True
            else:
                self.is_rot[d] = jt == int(mujoco.mjtJoint.mjJNT_HINGE)
        # mask[s, d]: dof d moves site s (its body is an ancestor-or-self of the site's body)
        parent = model.body_parentid
        self.mask = np.zeros((len(sites), nv), dtype=bool)
        for i, s in enumerate(sites):
            b, chain = int(model.site_bodyid[s]), set()
            while True:
                chain.add(b)
                if b == 0:
                    break
                b = int(parent[b])
            self.mask[i] = np.isin(self.body, list(chain))
        self.pairs = np.nonzero(self.mask & free_mask[None, :])
        self.scatter: list | None = None

    def closure_jacobian(
        self,
        mech: Mechanism,
        xaxis: np.ndarray,
        xanchor: np.ndarray,
        xmat: np.ndarray,
        p: np.ndarray,
        free: np.ndarray,
    ) -> np.ndarray:
        """d(closure residual)/d(free dofs), (N, n_closure, n_free), from frames of N poses.

        ``p`` (N, S, 3) are the positions of the sites given at construction (all first
        sites of the closures, then all second sites); only (site, dof) pairs where the
        dof moves the site are computed, and scattered straight into their rows.
        """
        n = len(p)
        site, dof = self.pairs
        joint = self.joint[dof]
        axes = xaxis[:, joint].copy()  # (N, P, 3)
        unit = self.kind[dof] == 1
        axes[:, unit] = np.eye(3)[self.column[dof][unit]]
        col = self.kind[dof] == 2
        if np.any(col):
            rot_t = np.swapaxes(xmat.reshape(n, -1, 3, 3), 2, 3)  # rows = frame axes
            axes[:, col] = rot_t[:, self.body[dof][col], self.column[dof][col]]
        rot_pair = self.is_rot[dof]
        lin = axes.copy()
        lever = p[:, site[rot_pair]] - xanchor[:, joint[rot_pair]]
        lin[:, rot_pair] = _cross(axes[:, rot_pair], lever)
        if self.scatter is None:
            self.scatter = _scatter_plan(mech, site, dof, rot_pair, free)
        out = np.zeros((n, mech.n_closure * len(free)))
        for flat, pick, sign, use_rot in self.scatter:
            vals = (axes if use_rot else lin)[:, pick]  # (N, k, 3)
            out[:, flat] += sign * vals.reshape(n, -1)
        return out.reshape(n, mech.n_closure, len(free))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (cheaper than np.cross on small batched arrays)."""
    return a[..., [1, 2, 0]] * b[..., [2, 0, 1]] - a[..., [2, 0, 1]] * b[..., [1, 2, 0]]


def _scatter_plan(mech, site, dof, rot_pair, free):
    """Index lists that place (site, dof) Jacobian entries into closure rows and free columns."""
    nc = len(mech.closures)
    offsets = np.cumsum([0] + [c.size for c in mech.closures])
    free_index = -np.ones(mech.model.nv, dtype=int)
    free_index[free] = np.arange(len(free))
    plan = []
    for side, sign in ((0, 1.0), (1, -1.0)):
        for use_rot in (False, True):
            rows, cols, pick = [], [], []
            for k in range(len(site)):
                s, d = site[k], dof[k]
                if (s >= nc) != bool(side) or free_index[d] < 0:
                    continue
                ci = s - side * nc
                if use_rot and (mech.closures[ci].kind != "weld" or not rot_pair[k]):
                    continue
                base = offsets[ci] + (3 if use_rot else 0)
                rows += [base, base + 1, base + 2]
                cols += [free_index[d]] * 3
                pick.append(k)
            if pick:
                flat = np.array(rows) * len(free) + np.array(cols)
                plan.append((flat, np.array(pick), sign, use_rot))
    return plan


def _jacobian(mech: Mechanism, axes: _DofAxes, frames: dict, ids: np.ndarray) -> np.ndarray:
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
        axes = _DofAxes(m, np.concatenate([a, b]), mech.free_dofs())
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
    axes: _DofAxes,
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
