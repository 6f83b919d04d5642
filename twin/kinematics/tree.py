"""MuJoCo's ``mj_kinematics`` in numpy, vectorised over many configurations.

MuJoCo computes one configuration per call; forward kinematics, its Newton closure solve and
the identification Jacobian need the frames of thousands. This module computes the same
quantities (body frames ``xpos``/``xmat``, joint ``xanchor``/``xaxis``, site frames) for N
configurations at once from the compiled ``MjModel`` alone, so it serves every machine the
MJCF describes through one code path:

* the tree's *structure* (parents, joint types and addresses, which axes are coordinate axes)
  is read once per model (:class:`TreePlan`), bodies of equal depth processed together;
* its *numbers* (``body_pos``, ``body_quat``, ``jnt_pos``, ``jnt_axis``, ``qpos0``,
  ``site_pos``, ``site_quat``) are read at every call, so a model edited in place (an
  injected error, a thermal effect) is followed exactly as ``mj_kinematics`` would.

Arrays are "structure of arrays" with the configurations last, which keeps every numpy
operation long and contiguous: positions (3, K, N), rotations (3, 3, K, N) (row, column),
configurations (nq, N). Mocap bodies are not supported (:class:`TreePlan` refuses them).
Tests hold the frames equal to MuJoCo's to round-off (tests/test_kinematics_fast.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

FREE = int(mujoco.mjtJoint.mjJNT_FREE)
BALL = int(mujoco.mjtJoint.mjJNT_BALL)
SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
# hinge axis classes: rotation about a coordinate axis is a cheap column rotation
AXIS_X, AXIS_Y, AXIS_Z, AXIS_GENERAL = 0, 1, 2, 3
# columns (a, b) mixed by a rotation about coordinate axis k, and the sign of sin on b
_COLUMNS = {AXIS_X: (1, 2), AXIS_Y: (2, 0), AXIS_Z: (0, 1)}


def as_index(ix: np.ndarray) -> np.ndarray | slice:
    """An index array as a slice when it is an arithmetic progression (a view, not a copy)."""
    ix = np.asarray(ix, dtype=int)
    if ix.size == 0:
        return ix
    if ix.size == 1:
        return slice(int(ix[0]), int(ix[0]) + 1)
    step = int(ix[1] - ix[0])
    if step > 0 and np.all(np.diff(ix) == step):
        return slice(int(ix[0]), int(ix[-1]) + 1, step)
    return ix


def dofs_moving_sites(model: mujoco.MjModel, sites, dofs) -> np.ndarray:
    """(S, len(dofs)) bool: the dof moves the site (its body is an ancestor-or-self of the
    site's body)."""
    dof_body = model.dof_bodyid[np.asarray(dofs, dtype=int)]
    out = np.zeros((len(sites), len(dof_body)), dtype=bool)
    for i, s in enumerate(sites):
        b, chain = int(model.site_bodyid[s]), set()
        while True:
            chain.add(b)
            if b == 0:
                break
            b = int(model.body_parentid[b])
        out[i] = np.isin(dof_body, list(chain))
    return out


@dataclass(frozen=True)
class JointGroup:
    """Joints of one kind in one slot of one depth level of the tree."""

    kind: int  # HINGE, SLIDE, BALL
    axis_class: int  # for hinges: AXIS_X/Y/Z (unit local axis, sign in ``sign``) or GENERAL
    local: np.ndarray | slice  # positions into the level's body list
    joints: np.ndarray  # joint ids
    sign: np.ndarray  # +1/-1 for coordinate-axis hinges (axis = sign * e_k)
    joint_index: np.ndarray | slice  # ``joints`` as an index (a slice when it can be)
    qpos_index: np.ndarray | slice  # their qpos addresses (1-dof joints), as an index


@dataclass(frozen=True)
class Level:
    bodies: np.ndarray | slice
    parents: np.ndarray | slice
    world_parent: bool  # every body's parent is the world
    parent_local: np.ndarray | slice  # the parents' positions in the previous level
    size: int  # bodies in the level
    free_local: np.ndarray  # positions (in bodies) of bodies moved by a free joint
    free_joints: np.ndarray
    groups: tuple[JointGroup, ...]  # in joint order within each body


class TreePlan:
    """The structure of a model's kinematic tree, read once (numbers are read per call)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        if np.any(model.body_mocapid >= 0):
            raise ValueError("mocap bodies are not supported by the numpy kinematic tree")
        self.nbody, self.njnt, self.nq = model.nbody, model.njnt, model.nq
        depth = np.zeros(model.nbody, dtype=int)
        for b in range(1, model.nbody):  # MuJoCo orders bodies parents first
            depth[b] = depth[model.body_parentid[b]] + 1
        self.levels: list[Level] = []
        previous = np.zeros(1, dtype=int)  # the world
        for d in range(1, int(depth.max(initial=0)) + 1):
            bodies = np.flatnonzero(depth == d)
            self.levels.append(self._level(model, bodies, previous))
            previous = bodies

    @staticmethod
    def _level(model: mujoco.MjModel, bodies: np.ndarray, previous: np.ndarray) -> Level:
        free_local, free_joints = [], []
        slots: dict[tuple[int, int, int], list[tuple[int, int, int]]] = {}
        for i, b in enumerate(bodies):
            adr, num = int(model.body_jntadr[b]), int(model.body_jntnum[b])
            if num == 1 and int(model.jnt_type[adr]) == FREE:
                free_local.append(i)
                free_joints.append(adr)
                continue
            for s in range(num):
                j = adr + s
                kind = int(model.jnt_type[j])
                if kind == FREE:
                    raise ValueError("a free joint must be the only joint of its body")
                axis_class, sign = AXIS_GENERAL, 1
                if kind == HINGE:
                    a = model.jnt_axis[j]
                    nz = np.flatnonzero(a != 0.0)
                    if nz.size == 1 and abs(a[nz[0]]) == 1.0:
                        axis_class, sign = int(nz[0]), int(np.sign(a[nz[0]]))
                slots.setdefault((s, kind, axis_class), []).append((i, j, sign))
        groups = []
        for (_, kind, axis_class), members in sorted(slots.items()):
            local, joints, signs = (np.array(x, dtype=int) for x in zip(*members, strict=True))
            adr = model.jnt_qposadr[joints]
            groups.append(
                JointGroup(
                    kind,
                    axis_class,
                    as_index(local),
                    joints,
                    signs.astype(float),
                    as_index(joints),
                    as_index(adr),
                )
            )
        parents = model.body_parentid[bodies].copy()
        return Level(
            as_index(bodies),
            as_index(parents),
            bool(np.all(parents == 0)),
            as_index(np.searchsorted(previous, parents)),
            len(bodies),
            np.array(free_local, int),
            np.array(free_joints, int),
            tuple(groups),
        )


def rotation_soa(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (3, 3, K) from quaternions (K, 4) (w, x, y, z), normalised first."""
    q = np.asarray(quat, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matvec(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """r (3, 3, G, N) applied to v (3, G, N or 1)."""
    return np.einsum("ikgn,kgn->ign", r, v)


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a (3, 3, G, N) @ b (3, 3, G, N or 1)."""
    return np.einsum("ikgn,kjgn->ijgn", a, b)


@dataclass
class TreeFrames:
    """Frames of N configurations (see the module docstring for the layout)."""

    xpos: np.ndarray  # (3, nbody, N)
    xmat: np.ndarray  # (3, 3, nbody, N)
    xanchor: np.ndarray  # (3, njnt, N)
    xaxis: np.ndarray  # (3, njnt, N)

    def site_positions(
        self, model: mujoco.MjModel, sites: np.ndarray, part: np.ndarray | None = None
    ) -> np.ndarray:
        """World positions (3, S, N) of ``sites`` (of the configurations ``part`` selects)."""
        sites = np.asarray(sites, dtype=int)
        body = model.site_bodyid[sites]
        xpos, xmat = self.xpos[:, body], self.xmat[:, :, body]
        if part is not None:
            xpos, xmat = xpos[..., part], xmat[..., part]
        local = model.site_pos[sites].T[:, :, None]
        return xpos + matvec(xmat, local)

    def site_rotations(
        self, model: mujoco.MjModel, sites: np.ndarray, part: np.ndarray | None = None
    ) -> np.ndarray:
        """World rotations (3, 3, S, N) of ``sites`` (of the configurations ``part`` selects)."""
        sites = np.asarray(sites, dtype=int)
        xmat = self.xmat[:, :, model.site_bodyid[sites]]
        if part is not None:
            xmat = xmat[..., part]
        quat = model.site_quat[sites]
        turned = np.flatnonzero(np.any(quat != np.array([1.0, 0.0, 0.0, 0.0]), axis=1))
        if turned.size == len(sites):
            return matmul(xmat, rotation_soa(quat)[..., None])
        if turned.size:  # sites with an identity rotation keep their body's (exactly)
            xmat[:, :, turned] = matmul(xmat[:, :, turned], rotation_soa(quat[turned])[..., None])
        return xmat


@dataclass(frozen=True)
class GroupNumbers:
    jpos: np.ndarray  # (3, G, 1) joint positions in the body frame
    offset: bool  # any joint away from its body's origin
    axis: np.ndarray  # (3, G, 1) joint axes in the body frame
    zero: np.ndarray  # (G, 1) qpos0 of 1-dof joints
    sign: np.ndarray | None  # (G, 1) of coordinate-axis hinges, None when all +1


@dataclass(frozen=True)
class TreeNumbers:
    """A model's numbers in the layout of :func:`tree_frames`, per level and group."""

    body_pos: list[np.ndarray | None]  # (3, G, 1) per level; None when all zero
    body_rot: list[np.ndarray | None]  # (3, 3, G, 1) per level; None when all identity
    groups: list[list[GroupNumbers]]


def tree_numbers(plan: TreePlan, model: mujoco.MjModel) -> TreeNumbers:
    """Read the numbers :func:`tree_frames` uses from ``model`` (structure ``plan``)."""
    pos, rot, groups = [], [], []
    for level in plan.levels:
        b = level.bodies
        bp = model.body_pos[b]
        pos.append(bp.T[:, :, None].copy() if np.any(bp != 0.0) else None)
        bq = model.body_quat[b]
        ident = np.all(bq == np.array([1.0, 0.0, 0.0, 0.0]))
        rot.append(None if ident else rotation_soa(bq)[..., None])
        numbers = []
        for g in level.groups:
            j = g.joints
            sign = None if np.all(g.sign > 0) else g.sign[:, None]
            numbers.append(
                GroupNumbers(
                    model.jnt_pos[j].T[:, :, None].copy(),
                    bool(np.any(model.jnt_pos[j] != 0.0)),
                    model.jnt_axis[j].T[:, :, None].copy(),
                    model.qpos0[model.jnt_qposadr[j]][:, None].copy(),
                    sign,
                )
            )
        groups.append(numbers)
    return TreeNumbers(pos, rot, groups)


def tree_frames(
    plan: TreePlan,
    model: mujoco.MjModel,
    qpos: np.ndarray,
    numbers: TreeNumbers | None = None,
) -> TreeFrames:
    """``mj_kinematics`` of configurations ``qpos`` (nq, N) of ``model`` (structure ``plan``;
    ``numbers`` from :func:`tree_numbers` of the same model, read now when not given)."""
    numbers = numbers or tree_numbers(plan, model)
    n = qpos.shape[1]
    xpos = np.empty((3, plan.nbody, n))
    xmat = np.empty((3, 3, plan.nbody, n))
    xpos[:, 0] = 0.0
    xmat[:, :, 0] = np.eye(3)[:, :, None]
    xanchor = np.empty((3, plan.njnt, n))  # every joint is written below
    xaxis = np.empty((3, plan.njnt, n))
    prev_pos = prev_rot = None  # the previous level's frames (contiguous: fast products)
    for li, level in enumerate(plan.levels):
        b = level.bodies
        bp, br = numbers.body_pos[li], numbers.body_rot[li]
        g = level.size
        if level.world_parent:  # the world frame is the identity: nothing to multiply
            pos = np.zeros((3, g, n)) if bp is None else np.repeat(bp, n, axis=2)
            rot = np.empty((3, 3, g, n))
            rot[...] = np.eye(3)[:, :, None, None] if br is None else br
        else:
            pl = level.parent_local
            pp, pr = prev_pos[:, pl], prev_rot[:, :, pl]
            pos = pp.copy() if bp is None else matvec(pr, bp) + pp
            rot = pr.copy() if br is None else matmul(pr, br)
        for g, gn in zip(level.groups, numbers.groups[li], strict=True):
            _apply_joints(g, gn, model, qpos, pos, rot, xanchor, xaxis)
        if level.free_local.size:
            fl, fj = level.free_local, level.free_joints
            adr = model.jnt_qposadr[fj]
            pos[:, fl] = qpos[adr[None, :] + np.arange(3)[:, None]]
            quat = qpos[adr[None, :] + np.arange(3, 7)[:, None]]  # (4, F, N)
            rot[:, :, fl] = _rotation_from_quat_soa(quat)
            xanchor[:, fj] = pos[:, fl]
            xaxis[:, fj] = model.jnt_axis[fj].T[:, :, None]
        xpos[:, b] = pos
        xmat[:, :, b] = rot
        prev_pos, prev_rot = pos, rot
    return TreeFrames(xpos, xmat, xanchor, xaxis)


def _rotation_from_quat_soa(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (3, 3, ...) from quaternions (4, ...), normalised first."""
    q = q / np.sqrt(np.sum(q * q, axis=0))
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _apply_joints(g: JointGroup, gn: GroupNumbers, model, qpos, pos, rot, xanchor, xaxis) -> None:
    """One group of joints, in place on the level's (pos, rot) and the joint frames."""
    loc, ji, adr = g.local, g.joint_index, g.qpos_index
    r = rot[:, :, loc]  # (3, 3, G, N)
    coordinate = g.kind == HINGE and g.axis_class != AXIS_GENERAL
    if coordinate:
        axis = r[:, g.axis_class] if gn.sign is None else r[:, g.axis_class] * gn.sign
    else:
        axis = matvec(r, gn.axis)
    anchor = pos[:, loc] + matvec(r, gn.jpos) if gn.offset else pos[:, loc]
    xaxis[:, ji] = axis
    xanchor[:, ji] = anchor
    if g.kind == SLIDE:
        pos[:, loc] += axis * (qpos[adr] - gn.zero)
        return
    if coordinate:
        theta = qpos[adr] - gn.zero
        if gn.sign is not None:
            theta *= gn.sign
        c, s = np.cos(theta), np.sin(theta)
        a, b = _COLUMNS[g.axis_class]
        ra, rb = r[:, a].copy(), r[:, b]  # rb is read before its column is written
        tmp = np.empty_like(ra)
        in_place = isinstance(loc, slice)  # columns written through views, else copied
        na = rot[:, a, loc] if in_place else np.empty_like(ra)
        nb = rot[:, b, loc] if in_place else np.empty_like(ra)
        np.multiply(c, ra, out=na)
        na += np.multiply(s, rb, out=tmp)
        np.multiply(c, rb, out=nb)
        nb -= np.multiply(s, ra, out=tmp)
        if not in_place:
            rot[:, a, loc], rot[:, b, loc] = na, nb
    else:
        if g.kind == HINGE:
            local = _axis_angle_soa(model.jnt_axis[g.joints], qpos[adr] - gn.zero)
        else:  # BALL: the quaternion in qpos
            start = model.jnt_qposadr[g.joints]
            local = _rotation_from_quat_soa(qpos[start[None, :] + np.arange(4)[:, None]])
        rot[:, :, loc] = matmul(r, local)
    if gn.offset:
        pos[:, loc] = anchor - matvec(rot[:, :, loc], gn.jpos)


def _axis_angle_soa(axis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Rotations (3, 3, G, N) about unit axes (G, 3) by angles (G, N) (Rodrigues)."""
    u = (axis / np.linalg.norm(axis, axis=1, keepdims=True)).T[:, :, None]  # (3, G, 1)
    c, s = np.cos(theta), np.sin(theta)
    t = 1.0 - c
    x, y, z = u
    return np.array(
        [
            [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
            [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
            [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
        ]
    )
