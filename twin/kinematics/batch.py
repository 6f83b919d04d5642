"""Batched forward kinematics: the same Newton as twin.kinematics.single_pose, many poses at once.

A serial chain (no free dof) needs no Newton: one kinematics pass.

Two engines, the same algorithm: by default the compiled kernels (twin.kinematics.compiled:
each pose's whole Newton in machine code, chunks of poses side by side on threads, since the
kernels release the GIL), else the numpy path, vectorised over poses. There each Newton step
computes the frames of every pose with the numpy kinematic tree (twin.kinematics.tree:
MuJoCo's ``mj_kinematics`` vectorised over poses), the closure residual and Jacobian from
them, and the step by elimination per closure (twin.kinematics.reduced: each limb's private
joints eliminated, a small system over the shared ones); numpy holds the GIL between its many
short operations, so a second thread adds at most ~10 %. Steps, damping of long steps,
tolerance, stall rule and failure are those of the single-pose solve; each pose is checked
against the same tolerance, and a pose that fails raises.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial

import mujoco
import numpy as np

from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics.compiled import (
    CompiledPlan,
    compiled_numbers,
    compiled_plan,
    kernels_pay,
    parallel_min,
    pose_chunks,
    processors,
    run_chunks,
    solve_compiled,
)
from twin.kinematics.single_pose import ACCEPT, MAX_ITER, MAX_STEP, TOLERANCE, check_commands
from twin.kinematics.structure import (
    PREDICT_MIN,
    FastKinematics,
    closure_residual_soa,
    difference_soa,
    fast_kinematics,
    integrate_soa,
    one_blas_thread,
)
from twin.kinematics.tree import TreeFrames, tree_frames
from twin.mechanism import Mechanism
from twin.rotations import quat_from_rotvec, quat_multiply

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


CHUNK = 2048  # most poses solved together: long numpy operations, arrays mostly in cache
CHUNK_ENTRIES = 2**19  # ... and at most about this many closure-matrix entries in a chunk
PARALLEL_MIN = 2048  # fewer poses than this run on one thread (threads cost more)


def forward_batch(
    mech: Mechanism,
    commands: np.ndarray,
    nthread: int = 0,
    start: np.ndarray | None = None,
    check_stroke: bool = True,
    compiled: bool | None = None,
) -> BatchSolution:
    """Forward kinematics for commands (N, A) (SI); raises ClosureError naming failed poses.

    ``start``: one configuration (nq,) or one per pose (N, nq), e.g. the previous solution
    when the same poses are solved again for slightly different parameters. ``nthread``: 0
    for one thread per processor (used only for many poses), else at most that many.
    ``compiled``: True, the compiled kernels (twin.kinematics.compiled) where they cover the
    machine, else the numpy path; False, the numpy path; None (default), the kernels where
    they pay for their start (twin.kinematics.compiled.kernels_pay). Both give the same
    solutions to round-off.
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
    q0 = np.asarray(mech.home_qpos if start is None else start, dtype=float)
    if q0.ndim == 2 and q0.shape != (n, m.nq):
        raise ClosureError(f"start must be ({m.nq},) or ({n}, {m.nq}), got {q0.shape}")
    qpos = np.array(np.broadcast_to(q0, (n, m.nq)))
    qpos[:, mech.actuator_qpos] = mech.joints_of_commands(commands)
    fk = fast_kinematics(mech)
    kernels = kernels_pay(fk, n) if compiled is None else compiled
    plan = compiled_plan(fk) if kernels else None
    if plan is not None:
        return _forward_compiled(fk, plan, qpos, commands, start is None, nthread)
    q = np.ascontiguousarray(qpos.T)  # (nq, N)
    if start is None and n >= PREDICT_MIN and fk.closure is not None:
        predict_start(fk, q, commands)
    residual = np.zeros(n)
    sites = np.zeros((3, 3 + 1, len(fk.out_sites), n))  # position, then rotation columns
    workers = 1 if n < PARALLEL_MIN else (nthread if nthread > 0 else (os.cpu_count() or 1))
    count = -(-n // _chunk_limit(fk))  # chunks of at most that many, as many per worker
    count = -(-count // workers) * workers
    chunks = pose_chunks(n, count)
    workers = max(1, min(len(chunks), workers))

    def work(k: int) -> int:
        its = 0
        for sl in chunks[k::workers]:
            qc = np.ascontiguousarray(q[:, sl])
            its = max(its, _solve_chunk(fk, qc, residual[sl], sites[..., sl]))
            q[:, sl] = qc
        return its

    with one_blas_thread():
        if workers == 1:
            iterations = work(0)
        else:
            with ThreadPoolExecutor(workers) as pool:
                iterations = max(pool.map(work, range(workers)))
    _raise_unclosed(mech, residual)
    return BatchSolution(
        qpos=np.ascontiguousarray(q.T),
        tool_rotation=np.moveaxis(sites[:, 1:, 0], -1, 0).copy(),
        tool_position=sites[:, 0, 0].T.copy(),
        targets=np.moveaxis(sites[:, 0, 1:], (0, 1, 2), (2, 1, 0)).copy(),
        residual=residual,
        iterations=iterations,
    )


COMPILED_PARALLEL_MIN = 256  # fewer poses than this run on one thread (compiled kernels)


def _forward_compiled(
    fk: FastKinematics,
    plan: CompiledPlan,
    qpos: np.ndarray,
    commands: np.ndarray,
    cold: bool,
    nthread: int,
) -> BatchSolution:
    """forward_batch on the compiled kernels: ``qpos`` (N, nq) the starts with the actuators
    at their commands (moved by the linear predictor when ``cold``)."""
    n = len(qpos)
    if cold and n >= PREDICT_MIN and fk.closure is not None:
        qt = np.ascontiguousarray(qpos.T)
        predict_start(fk, qt, commands)
        qpos = qt.T
    q = np.ascontiguousarray(qpos)
    numbers = compiled_numbers(fk)
    out_pos = np.empty((n, len(plan.out_sites), 3))
    out_rot = np.empty((n, 3, 3))
    residual = np.empty(n)
    iterations = np.zeros(n, dtype=np.int64)
    least = parallel_min(fk, COMPILED_PARALLEL_MIN)
    chunks = pose_chunks(n, 1 if n < least else (nthread or processors()))

    def work(sl: slice) -> None:
        solve_compiled(plan, numbers, q[sl], out_pos[sl], out_rot[sl], residual[sl],
                       iterations[sl], (TOLERANCE, ACCEPT, MAX_ITER, MAX_STEP))  # fmt: skip

    run_chunks(work, chunks)
    _raise_unclosed(fk.mech, residual)
    return BatchSolution(
        qpos=q,
        tool_rotation=out_rot,
        tool_position=out_pos[:, 0].copy(),
        targets=out_pos[:, 1:].copy(),
        residual=residual,
        iterations=int(iterations.max(initial=0)),
    )


def _raise_unclosed(mech: Mechanism, residual: np.ndarray) -> None:
    failed = np.flatnonzero(~(residual < ACCEPT))
    if failed.size:
        raise ClosureError(
            f"batched forward kinematics of '{mech.name}': {failed.size} of {len(residual)} "
            f"poses did not close (first: pose {failed[0]}, residual {residual[failed[0]]:.3g})"
        )


def _chunk_limit(fk: FastKinematics) -> int:
    """Most poses in one chunk: CHUNK, fewer where the closure matrices of each pose are
    large (measured: the hexapod's 432 entries per pose ran best at 1024 poses, the
    polisher's 162 at 2048)."""
    cs = fk.closure
    if cs is None:
        return CHUNK
    s = len(cs.shared)
    entries = sum(g.rows * (g.k + s + 1) * len(g.closures) for g in cs.groups)
    return max(256, min(CHUNK, CHUNK_ENTRIES // max(entries, 1)))


def _solve_chunk(fk: FastKinematics, q: np.ndarray, residual: np.ndarray, out: np.ndarray) -> int:
    """Newton on one chunk of configurations q (nq, n), in place on q, residual and out."""
    mech, m = fk.mech, fk.model
    n = q.shape[1]
    cs = fk.closure
    numbers = fk.numbers()
    if cs is None:  # a serial chain: every joint commanded, nothing to solve
        frames = tree_frames(fk.tree, m, q, numbers)
        _store(fk, frames, out, np.ones(n, dtype=bool), np.arange(n))
        residual[:] = 0.0
        return 0
    welds = any(c.kind == "weld" for c in mech.closures)
    active = np.arange(n)
    best = np.full(n, np.inf)
    stall = np.zeros(n, dtype=int)
    it = 0
    for it in range(MAX_ITER + 1):
        qa = q[:, active]
        frames = tree_frames(fk.tree, m, qa, numbers)
        pos = frames.site_positions(m, cs.sites)
        rot = frames.site_rotations(m, cs.sites) if welds else None
        r = closure_residual_soa(mech, pos, rot)
        err = np.max(np.abs(r), axis=0)
        residual[active] = err
        stall[active] = np.where(err >= 0.5 * best[active], stall[active] + 1, 0)
        best[active] = np.minimum(best[active], err)
        done = (err < TOLERANCE) | ((stall[active] >= 3) & (best[active] < ACCEPT))
        done |= ~np.isfinite(err)
        if it == MAX_ITER:
            done[:] = True
        if np.any(done):
            _store(fk, frames, out, done, active)
        keep = ~done
        if not np.any(keep):
            break
        part = None if np.all(keep) else keep
        rhs = -r[:, None]
        mats = cs.matrices(frames, pos, rhs, part)
        step = cs.solve(mats, rebuild=partial(cs.matrices, frames, pos, rhs, part))[:, 0]
        norm = np.sqrt(np.sum(step * step, axis=0))
        step *= np.minimum(1.0, MAX_STEP / np.maximum(norm, 1e-300))
        ids = active[keep]
        qk = q[:, ids]
        integrate_soa(fk, qk, step)
        q[:, ids] = qk
        active = ids
    return it


def _store(
    fk: FastKinematics, frames: TreeFrames, out: np.ndarray, done: np.ndarray, active: np.ndarray
) -> None:
    """Tool and target frames of the poses that are done (``done`` over ``active``) into
    ``out`` (3, 4, S, N): column 0 the sites' positions, columns 1-3 the tool's rotation."""
    part = None if np.all(done) else done
    m = fk.model
    ids = active[done]
    pos = frames.site_positions(m, fk.out_sites, part)  # (3, S, k)
    out[:, 0, :, ids] = np.moveaxis(pos, -1, 0)
    rot = frames.site_rotations(m, fk.out_sites[:1], part)  # (3, 3, 1, k)
    out[:, 1:, 0, ids] = rot[:, :, 0]


CURVATURE_MIN = 1024  # from this many cold starts on, the predictor's second-order term too
CURVATURE_STEP = 1e-3  # finite-difference step of the curvature, in command units (m, rad)


def curvature(fk: FastKinematics) -> np.ndarray | None:
    """Second derivatives (n_free, A, A) of the closed chain's free dofs with respect to the
    commands at the home configuration, by central differences of closed solutions (batched,
    from the closed home configuration), or None when a difference point does not close.
    Kept with the predictor: it depends on the model's numbers."""
    pred = fk.predictor()
    if pred is None:
        return None
    if fk._curvature_key == fk._predictor_key:
        return fk._curvature
    home, home_cmd, _ = pred
    a = len(home_cmd)
    h = CURVATURE_STEP
    signs = np.array([(1, 1), (1, -1), (-1, 1), (-1, -1)], dtype=float)
    pairs = [(i, j) for i in range(a) for j in range(i, a)]
    cmds = np.array(
        [
            home_cmd + h * (si * np.eye(a)[i] + sj * np.eye(a)[j])
            for i, j in pairs
            for si, sj in signs
        ]
    )
    try:
        sol = forward_batch(fk.mech, cmds, start=home, check_stroke=False)
    except (ClosureError, WorkspaceError):
        out = None
    else:
        d = difference_soa(fk, np.repeat(home[:, None], len(cmds), axis=1), sol.qpos.T)
        d = d.reshape(d.shape[0], len(pairs), 4)
        second = (d[..., 0] - d[..., 1] - d[..., 2] + d[..., 3]) / (4.0 * h * h)
        out = np.zeros((d.shape[0], a, a))
        for k, (i, j) in enumerate(pairs):
            out[:, i, j] = out[:, j, i] = second[:, k]
    fk._curvature, fk._curvature_key = out, fk._predictor_key
    return out


def predict_start(fk: FastKinematics, q: np.ndarray, commands: np.ndarray) -> None:
    """Cold starts (nq, N) moved in place by the predictor: the first-order step along the
    closed chain's sensitivity at home (FastKinematics.predictor) and, from CURVATURE_MIN
    poses on, the second-order term of :func:`curvature`, which leaves Newton a start about
    five times closer and saves it about half a step a pose (computing the curvature costs
    about as much as solving a thousand poses saves, hence the threshold)."""
    pred = fk.predictor()
    if pred is None:
        return
    home, home_cmd, sens = pred
    dc = (commands - home_cmd).T  # (A, N)
    step = sens @ dc  # (n_free, N)
    second = curvature(fk) if commands.shape[0] >= CURVATURE_MIN else None
    if second is not None:
        outer = (dc[:, None, :] * dc[None, :, :]).reshape(-1, dc.shape[1])  # (A * A, N)
        step += 0.5 * (second.reshape(second.shape[0], -1) @ outer)
    norm = np.sqrt(np.sum(step * step, axis=0))
    step *= np.minimum(1.0, MAX_STEP / np.maximum(norm, 1e-300))
    q[:] = home[:, None]
    integrate_soa(fk, q, step)
    q[fk.mech.actuator_qpos] = fk.mech.joints_of_commands(commands).T
