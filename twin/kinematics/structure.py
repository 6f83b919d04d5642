"""What batched kinematics reads once per machine, and the pieces its Newton steps share.

* :class:`KinematicStructure`: the numpy kinematic tree's plan (twin.kinematics.tree), the
  closure structure and its static pivots (twin.kinematics.reduced), index arrays. It depends
  only on the model's structure (bodies, joints, closures), so every model of one machine
  (each injected parameter set) shares one, kept in a small bounded memo;
* :class:`FastKinematics`: one mechanism's structure plus what depends on its numbers (the
  tree's numbers, the cold-start predictor), read again whenever the model's numbers change;
* closure residuals and ``mj_integratePos`` in the "structure of arrays" layout.
"""

from __future__ import annotations

import contextlib
import functools
from collections import OrderedDict
from collections.abc import Callable
from typing import Any, TypeVar

import mujoco
import numpy as np

from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics.closure import closure_jacobian, update_kinematics
from twin.kinematics.reduced import ClosureStructure
from twin.kinematics.single_pose import forward
from twin.kinematics.tree import TreeNumbers, TreePlan, tree_frames, tree_numbers
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_quat, quat_from_rotvec, quat_multiply, rotvec_from_matrix

FREE = int(mujoco.mjtJoint.mjJNT_FREE)
HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
MEMO_SIZE = 16  # machine structures kept
_STRUCTURES: OrderedDict[bytes, KinematicStructure] = OrderedDict()


F = TypeVar("F", bound=Callable[..., Any])


@functools.cache
def _blas_controller():
    """threadpoolctl's view of the BLAS libraries loaded (once: inspecting them costs ~1 ms,
    limiting through it ~30 us); None without threadpoolctl."""
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:
        return None
    return ThreadpoolController()


def one_blas_thread() -> contextlib.AbstractContextManager:
    """BLAS on one thread for the enclosed numpy work.

    The kinematics' and the identification's matrices are small (6 x 6 to 2304 x 60): a
    second BLAS thread only waits for the first, and under load it made a 2304 x 54 ``J^T J``
    take 64 ms instead of 0.19 ms. Batched kinematics, the identification Jacobian and
    ``calib.fit.identification`` run inside this (results never depend on it: one thread or many
    give
    the same numbers to round-off, and every check has a tolerance)."""
    controller = _blas_controller()
    return contextlib.nullcontext() if controller is None else controller.limit(limits=1)


def on_one_blas_thread(fn: F) -> F:
    """``fn`` run inside :func:`one_blas_thread` (for entry points whose whole body is small
    matrix work)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with one_blas_thread():
            return fn(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def structure_key(mech: Mechanism) -> bytes:
    """Everything about a mechanism's model that the structure depends on (not its numbers,
    except the joint axes, whose coordinate-axis classes the tree uses)."""
    m = mech.model
    parts = [
        np.array([m.nbody, m.njnt, m.nq, m.nv, m.nsite, mech.tool_site]),
        m.body_parentid,
        m.body_jntadr,
        m.body_jntnum,
        m.body_mocapid,
        m.jnt_type,
        m.jnt_qposadr,
        m.jnt_dofadr,
        m.jnt_bodyid,
        m.jnt_axis,
        m.dof_bodyid,
        m.dof_jntid,
        m.site_bodyid,
        mech.actuator_dofs,
        mech.target_sites,
        np.array([(c.site_a, c.site_b, c.size) for c in mech.closures]).reshape(-1),
        m.key_qpos.reshape(-1) if m.nkey else np.zeros(0),
    ]
    return b"|".join(np.ascontiguousarray(x).tobytes() for x in parts)


PREDICT_MIN = 16  # from this many poses on, cold starts use the linear predictor


def model_fingerprint(model: mujoco.MjModel) -> bytes:
    """The numbers of a model kinematics reads (a model edited in place changes them)."""
    return b"".join(
        np.ascontiguousarray(a).tobytes()
        for a in (
            model.body_pos,
            model.body_quat,
            model.jnt_pos,
            model.jnt_axis,
            model.qpos0,
            model.site_pos,
            model.site_quat,
        )
    )


class KinematicStructure:
    """The tree plan, the closure structure (with static pivots) and index arrays."""

    def __init__(self, mech: Mechanism) -> None:
        self.tree = TreePlan(mech.model)
        self.closure = ClosureStructure(mech) if mech.free_dofs().size else None
        if self.closure is not None:  # static pivots from the home configuration
            home = mech.home_qpos[:, None].copy()
            frames = tree_frames(self.tree, mech.model, home)
            pos = frames.site_positions(mech.model, self.closure.sites)
            self.closure.order_rows(frames, pos)
        self.out_sites = np.concatenate([[mech.tool_site], mech.target_sites]).astype(int)
        m = mech.model
        free = mech.free_dofs()
        simple = np.isin(m.jnt_type[m.dof_jntid[free]], (HINGE, SLIDE))
        self.simple_dof = free[simple]
        self.simple_qpos = m.jnt_qposadr[m.dof_jntid[free[simple]]]
        self.multi_joints = sorted({int(m.dof_jntid[d]) for d in free[~simple]})
        self.free = free
        self.free_position = {int(d): i for i, d in enumerate(free)}
        self.simple_rows = np.array([self.free_position[int(d)] for d in self.simple_dof], int)


def kinematic_structure(mech: Mechanism) -> KinematicStructure:
    """The structure of ``mech``'s machine, built once per structure (a bounded memo)."""
    key = structure_key(mech)
    found = _STRUCTURES.get(key)
    if found is None:
        found = KinematicStructure(mech)
        _STRUCTURES[key] = found
        while len(_STRUCTURES) > MEMO_SIZE:
            _STRUCTURES.popitem(last=False)
    else:
        _STRUCTURES.move_to_end(key)
    return found


class FastKinematics:
    """One mechanism's :class:`KinematicStructure`, its tree numbers and cold-start predictor;
    numbers and predictor are recomputed whenever the model's numbers change."""

    def __init__(self, mech: Mechanism) -> None:
        self.mech = mech
        self.model = mech.model
        st = kinematic_structure(mech)
        self.structure = st
        self.tree, self.closure, self.out_sites = st.tree, st.closure, st.out_sites
        self.simple_dof, self.simple_qpos = st.simple_dof, st.simple_qpos
        self.multi_joints, self.free_position = st.multi_joints, st.free_position
        self.simple_rows = st.simple_rows  # rows of the simple dofs in a step over free dofs
        self._predictor_key: bytes | None = None
        self._predictor: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._numbers_key: bytes | None = None
        self._numbers: TreeNumbers | None = None
        self._curvature_key: bytes | None = None  # see curvature()
        self._curvature: np.ndarray | None = None

    def numbers(self) -> TreeNumbers:
        """The model's numbers for the tree, read again whenever they changed."""
        key = model_fingerprint(self.model)
        if key != self._numbers_key or self._numbers is None:
            self._numbers = tree_numbers(self.tree, self.model)
            self._numbers_key = key
        return self._numbers

    def predictor(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(closed home configuration, its actuator values, d q_free / d commands) or None.

        A cold start from the home configuration with the actuators moved to their commands
        is far from closed; a first-order step along the closed chain's sensitivity at home
        starts Newton within the square of the commanded motion, saving one or two steps.
        """
        key = model_fingerprint(self.model)
        if key != self._predictor_key:
            self._predictor_key, self._predictor = key, None
            mech = self.mech
            try:
                home = forward(mech, mech.home_commands, check_stroke=False)
            except (ClosureError, WorkspaceError):
                return None
            update_kinematics(mech, home.qpos)
            jac = closure_jacobian(mech)
            sens = -np.linalg.lstsq(
                jac[:, mech.free_dofs()], jac[:, mech.actuator_dofs], rcond=None
            )[0]
            self._predictor = (home.qpos, home.actuators, sens)
        return self._predictor


def fast_kinematics(mech: Mechanism) -> FastKinematics:
    """The mechanism's :class:`FastKinematics`, built on first use and kept with it."""
    fk = mech.__dict__.get("_fast_kinematics")
    if fk is None or fk.model is not mech.model:
        fk = FastKinematics(mech)
        mech.__dict__["_fast_kinematics"] = fk
    return fk


def rotvec_soa(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (3, ...) of rotation matrices (3, 3, ...) (angle in [0, pi])."""
    v = 0.5 * np.stack([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    sin = np.sqrt(np.sum(v * v, axis=0))
    cos = 0.5 * (r[0, 0] + r[1, 1] + r[2, 2] - 1.0)
    angle = np.arctan2(sin, cos)
    scale = np.where(sin > 1e-300, angle / np.where(sin > 1e-300, sin, 1.0), 1.0)
    out = v * scale
    near_pi = cos < -0.9  # the axis from the skew part loses accuracy: the exact formula
    if np.any(near_pi):
        mats = np.moveaxis(r[:, :, near_pi], -1, 0)
        out[:, near_pi] = rotvec_from_matrix(mats).T
    return out


def closure_residual_soa(mech: Mechanism, pos: np.ndarray, rot: np.ndarray | None) -> np.ndarray:
    """Stacked closure residuals (n_closure, N) from the closure sites' positions (3, 2C, N)
    and, for welds, rotations (3, 3, 2C, N) (first sites, then second)."""
    nc = len(mech.closures)
    n = pos.shape[-1]
    out = np.empty((mech.n_closure, n))
    dpos = pos[:, :nc] - pos[:, nc:]
    welds = [i for i, c in enumerate(mech.closures) if c.kind == "weld"]
    drot = None
    if welds and rot is not None:
        ra, rb = rot[:, :, welds], rot[:, :, [nc + i for i in welds]]
        drot = rotvec_soa(np.einsum("ikcn,jkcn->ijcn", ra, rb))
    row = 0
    w = 0
    for i, c in enumerate(mech.closures):
        out[row : row + 3] = dpos[:, i]
        if c.kind == "weld":
            out[row + 3 : row + 6] = drot[:, w]
            w += 1
        row += c.size
    return out


def integrate_soa(fk: FastKinematics, q: np.ndarray, step: np.ndarray) -> None:
    """``mj_integratePos`` with unit time step, in place on q (nq, N); step (n_free, N)."""
    m = fk.model
    pos_in_free = fk.free_position
    if fk.simple_dof.size:
        q[fk.simple_qpos] += step[fk.simple_rows]
    for j in fk.multi_joints:
        qa, da = int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])
        if int(m.jnt_type[j]) == FREE:
            rows = [pos_in_free[da + k] for k in range(6)]
            q[qa : qa + 3] += step[rows[:3]]
            qa, rows = qa + 3, rows[3:]
        else:
            rows = [pos_in_free[da + k] for k in range(3)]
        quat = quat_multiply(q[qa : qa + 4].T, quat_from_rotvec(step[rows].T))
        q[qa : qa + 4] = (quat / np.linalg.norm(quat, axis=1, keepdims=True)).T


def difference_soa(fk: FastKinematics, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """The step (n_free, N) that :func:`integrate_soa` takes from q0 to q1 (nq, N): the
    inverse of ``mj_integratePos`` over the free dofs (rotation vectors in the body frame for
    ball and free joints)."""
    m = fk.model
    out = np.zeros((len(fk.structure.free), q0.shape[1]))
    if fk.simple_dof.size:
        out[fk.simple_rows] = q1[fk.simple_qpos] - q0[fk.simple_qpos]
    for j in fk.multi_joints:
        qa, da = int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])
        if int(m.jnt_type[j]) == FREE:
            rows = [fk.free_position[da + k] for k in range(6)]
            out[rows[:3]] = q1[qa : qa + 3] - q0[qa : qa + 3]
            qa, rows = qa + 3, rows[3:]
        else:
            rows = [fk.free_position[da + k] for k in range(3)]
        conj = q0[qa : qa + 4].T * np.array([1.0, -1.0, -1.0, -1.0])
        turn = quat_multiply(conj, q1[qa : qa + 4].T)
        out[rows] = rotvec_from_matrix(matrix_from_quat(turn)).T
    return out
