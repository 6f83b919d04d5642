"""The compiled kernels' side in Python: the arrays they read, built from the MJCF.

twin.kinematics.batch calls :func:`solve_compiled` (forward kinematics), and
twin.kinematics.sensitivity_compiled the identification Jacobian's kernel, for every machine whose
closure system the kernels handle (all but an under-determined reduced system, and for the
Jacobian an over-determined one: those go through the numpy path). The structure arrays
(tree, closures, elimination columns, joint motions) depend only on the machine's
structure and are kept with its :class:`~twin.kinematics.structure.KinematicStructure`; the
numbers (body and joint frames, site offsets) are read from the model at every call, so an
edited model (an injected error, an effect) is followed exactly as by ``mj_kinematics``.
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.kinematics.structure import FastKinematics, model_fingerprint

FREE = int(mujoco.mjtJoint.mjJNT_FREE)
BALL = int(mujoco.mjtJoint.mjJNT_BALL)


@dataclass(frozen=True)
class CompiledPlan:
    """The structure the kernels read (tuples in the order newton_batch unpacks them)."""

    structure: tuple[np.ndarray, ...]
    closure: tuple[np.ndarray, ...]
    dofs: tuple[np.ndarray, ...]
    motion: tuple[np.ndarray, ...]
    out_sites: np.ndarray


def int_array(x) -> np.ndarray:
    """``x`` as a contiguous int64 array (the kernels' index type)."""
    return np.ascontiguousarray(np.asarray(x, dtype=np.int64))


# a serial chain of fewer poses than this is solved on the numpy path: there its explicit
# forward kinematics and Jacobian cost some 0.2-0.5 ms more per call (20-256 poses of a 6R
# arm), where the kernels' first use in a process (importing numba, loading the cached
# machine code) costs half a second or more: a command line on a small serial campaign
# answers without it. A serial chain has no Newton: the two paths compute the same
# expressions (bitwise equal fits of the 6R arm and the UR5 here); a closed chain always
# takes the kernels (its Newton stops within tolerance, the paths' stops differ)
SERIAL_KERNEL_MIN = 64


# a serial chain's kernel work is a fraction of a microsecond per pose (a 6R arm: 256 poses'
# forward kinematics in 0.07 ms, their Jacobian in 0.1 ms), less than handing a chunk to a
# pool thread and waiting for it; below this many poses it runs in the calling thread
SERIAL_PARALLEL_MIN = 4096


def parallel_min(fk: FastKinematics, closed_min: int) -> int:
    """The fewest poses split over threads: ``closed_min`` for a closed chain (a Newton or an
    adjoint solve per pose), SERIAL_PARALLEL_MIN for a serial one."""
    return closed_min if fk.closure is not None else SERIAL_PARALLEL_MIN


def kernels_pay(fk: FastKinematics, n_poses: int) -> bool:
    """Whether ``n_poses`` poses of ``fk``'s machine go to the compiled kernels by default:
    a closed chain always, a serial chain from SERIAL_KERNEL_MIN poses."""
    return fk.closure is not None or n_poses >= SERIAL_KERNEL_MIN


def compiled_plan(fk: FastKinematics) -> CompiledPlan | None:
    """The plan of ``fk``'s machine (kept with its structure), or None when the kernels do
    not cover it (a reduced closure system with fewer equations than shared unknowns)."""
    st = fk.structure
    if "_compiled_plan" in st.__dict__:
        return st.__dict__["_compiled_plan"]
    plan = _build_plan(fk)
    st.__dict__["_compiled_plan"] = plan
    return plan


def _build_plan(fk: FastKinematics) -> CompiledPlan | None:
    mech, m = fk.mech, fk.model
    cs = fk.closure
    nc = len(mech.closures)
    structure = (
        int_array(m.body_parentid),
        int_array(m.body_jntadr),
        int_array(m.body_jntnum),
        int_array(m.jnt_type),
        int_array(m.jnt_qposadr),
        int_array(m.site_bodyid),
    )
    if cs is None:  # a serial chain: no closure, no free dof
        none = np.zeros(0, dtype=np.int64)
        closure = (
            none,
            none,
            none,
            none,
            np.zeros((0, 0), np.int64),
            none,
            np.zeros((0, 0), np.uint8),
            True,
        )
        dofs = (none, none, none, none, np.zeros(0, np.bool_))
    else:
        rows = np.array([c.size for c in mech.closures], dtype=np.int64)
        k = np.array([cs.groups[cs.group_of[c]].k for c in range(nc)], dtype=np.int64)
        if int(np.sum(rows - k)) < len(cs.shared):
            return None
        private = np.zeros((nc, int(k.max(initial=0))), dtype=np.int64)
        for c in range(nc):
            g = cs.groups[cs.group_of[c]]
            private[c, : g.k] = g.private[cs.slot_of[c]]
        closure = (
            int_array(cs.sites),
            rows,
            int_array(cs.row_offset),
            k,
            private,
            int_array(cs.shared),
            np.ascontiguousarray(cs.site_moves, dtype=np.uint8),
            bool(cs.square),
        )
        dofs = (
            int_array(cs.dof_kind),
            int_array(cs.dof_joint),
            int_array(cs.dof_body),
            int_array(cs.dof_col),
            np.ascontiguousarray(cs.dof_rot, dtype=np.bool_),
        )
    multi = fk.multi_joints
    multi_rows = np.full((len(multi), 6), -1, dtype=np.int64)
    for i, j in enumerate(multi):
        da = int(m.jnt_dofadr[j])
        width = 6 if int(m.jnt_type[j]) == FREE else 3
        multi_rows[i, :width] = [fk.free_position[da + t] for t in range(width)]
    motion = (
        int_array(fk.simple_qpos),
        int_array(fk.simple_rows),
        int_array(m.jnt_type[multi]) if multi else np.zeros(0, np.int64),
        int_array(m.jnt_qposadr[multi]) if multi else np.zeros(0, np.int64),
        multi_rows,
    )
    return CompiledPlan(structure, closure, dofs, motion, int_array(fk.out_sites))


def _rotations(quat: np.ndarray) -> np.ndarray:
    """(K, 3, 3) from quaternions (K, 4), normalised (as twin.kinematics.tree)."""
    q = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    w, x, y, z = q.T
    out = np.empty((len(q), 3, 3))
    out[:, 0] = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], 1)
    out[:, 1] = np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], 1)
    out[:, 2] = np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1)
    return out


def model_numbers(m: mujoco.MjModel) -> tuple[np.ndarray, ...]:
    """The numbers the kernels read, in the order newton_batch unpacks them: body offsets,
    rotations and whether each turns, joint positions and whether each is off its body's
    origin, joint axes (as given and unit) with their class (0-2 a coordinate axis, signed
    by ``sign``; 3 any other), qpos0, site offsets, rotations and whether each turns."""
    ident = np.array([1.0, 0.0, 0.0, 0.0])
    axis = np.ascontiguousarray(m.jnt_axis, dtype=float)
    norm = np.linalg.norm(axis, axis=1, keepdims=True)
    unit = axis / np.where(norm > 0, norm, 1.0)
    nonzero = axis != 0.0
    single = (nonzero.sum(axis=1) == 1) & (np.abs(axis).max(axis=1, initial=0.0) == 1.0)
    cls = np.where(single, np.argmax(nonzero, axis=1), 3).astype(np.int64)
    sign = np.where(single, axis[np.arange(len(axis)), np.minimum(cls, 2)], 1.0)
    return (
        np.ascontiguousarray(m.body_pos, dtype=float),
        _rotations(np.asarray(m.body_quat, dtype=float)),
        np.ascontiguousarray(np.any(m.body_quat != ident, axis=1)),
        np.ascontiguousarray(m.jnt_pos, dtype=float),
        np.ascontiguousarray(np.any(m.jnt_pos != 0.0, axis=1)),
        axis,
        np.ascontiguousarray(unit),
        np.ascontiguousarray(cls),
        np.ascontiguousarray(sign, dtype=float),
        np.ascontiguousarray(m.qpos0, dtype=float),
        np.ascontiguousarray(m.site_pos, dtype=float),
        _rotations(np.asarray(m.site_quat, dtype=float)) if m.nsite else np.zeros((0, 3, 3)),
        np.ascontiguousarray(np.any(m.site_quat != ident, axis=1)),
    )


def compiled_numbers(fk: FastKinematics) -> tuple[np.ndarray, ...]:
    """:func:`model_numbers` of ``fk``'s model, read again whenever its numbers changed."""
    key = model_fingerprint(fk.model)
    found = fk.__dict__.get("_compiled_numbers")
    if found is None or found[0] != key:
        found = (key, model_numbers(fk.model))
        fk.__dict__["_compiled_numbers"] = found
    return found[1]


def solve_compiled(
    plan: CompiledPlan,
    numbers: tuple[np.ndarray, ...],
    qs: np.ndarray,
    out_pos: np.ndarray,
    out_rot: np.ndarray,
    residual: np.ndarray,
    iterations: np.ndarray,
    settings: tuple[float, float, int, float],
) -> None:
    """Forward kinematics of the starts ``qs`` (n, nq) (actuators at their commands), in place
    on every array: qs the closed configurations, out_pos (n, S, 3) the output sites,
    out_rot (n, 3, 3) the tool's rotation, residual and iterations (n,). ``settings``: the
    Newton's (tolerance, accept, max_iter, max_step), those of twin.kinematics.single_pose.

    The kernel works on arrays of this call's own, copied in and out: numba counts the
    references to an array's buffer atomically at every view and call, and threads sharing
    one buffer (halves of one batch, the model's numbers) would contend for its count."""
    from twin.kinematics.kernels import newton_batch  # compiles on first use

    own = own_copy
    q = qs.copy()
    pos, rot = np.empty(out_pos.shape), np.empty(out_rot.shape)
    res, its = np.empty(residual.shape), np.empty(iterations.shape, dtype=np.int64)
    newton_batch(
        q,
        own(plan.structure),
        own(numbers),
        own(plan.closure),
        own(plan.dofs),
        own(plan.motion),
        plan.out_sites.copy(),
        (float(settings[0]), float(settings[1]), int(settings[2]), float(settings[3])),
        pos,
        rot,
        res,
        its,
    )
    qs[:], out_pos[:], out_rot[:], residual[:], iterations[:] = q, pos, rot, res, its


def own_copy(arrays: tuple) -> tuple:
    """The arrays of a tuple copied (other items as they are)."""
    return tuple(a.copy() if isinstance(a, np.ndarray) else a for a in arrays)


@functools.cache
def processors() -> int:
    """Processors this process may run on (read once)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # not on every platform
        return os.cpu_count() or 1


POOL_PREFIX = "pkm-kinematics"
_pool: tuple[int, ThreadPoolExecutor] | None = None
_pool_lock = threading.Lock()


def _shared_pool(workers: int) -> ThreadPoolExecutor:
    """One pool of threads kept for the process (starting threads for every call cost more
    than a small batch's work); made anew in a forked child or when more workers are asked."""
    global _pool
    with _pool_lock:
        if _pool is None or _pool[0] != os.getpid() or _pool[1]._max_workers < workers:
            _pool = (os.getpid(), ThreadPoolExecutor(workers, thread_name_prefix=POOL_PREFIX))
        return _pool[1]


def pose_chunks(n: int, workers: int) -> list[slice]:
    """``n`` poses in at most ``workers`` contiguous chunks of (nearly) equal size."""
    size = -(-n // max(1, workers))
    return [slice(i, min(n, i + size)) for i in range(0, n, size)]


def run_chunks(work: Callable[[slice], None], chunks: Sequence[slice]) -> None:
    """``work(chunk)`` for every chunk, side by side on the kept pool (the kernels release the
    GIL), the first in the calling thread (it would only wait: one hand-off fewer, and on
    a busy machine no wait for a pool thread to be scheduled); every chunk in the calling
    thread when there is one or the caller is itself a pool thread (no nested waits on the
    pool). Each chunk writes its own poses: the results do not depend on who runs it."""
    if len(chunks) == 1 or threading.current_thread().name.startswith(POOL_PREFIX):
        for sl in chunks:
            work(sl)
        return
    futures = [_shared_pool(len(chunks) - 1).submit(work, sl) for sl in chunks[1:]]
    try:
        work(chunks[0])
    finally:
        for f in futures:  # every chunk finished (or failed) before the caller goes on
            f.exception()
    for f in futures:
        f.result()
