"""Self-collision and the floor, from the machine's own geoms (MuJoCo contacts).

Every geom counts as the machine's shape, whatever its ``contype``/``conaffinity`` (models
often disable contacts for simulation; a plan must still keep the links apart). A contact
between two geoms is a collision unless MuJoCo's own filters would drop it (the same body or
bodies welded together; a body and its parent, here the world included) or the bodies are
joined by a closure (an equality constraint: the chain is built to touch there), or the pair
already touches at the home configuration (parts mounted against each other, like a leg's
foot on its base plate). The floor is a height (``floor_z``, m, base frame) below which no
geom of a moving body may reach; a model's own plane geoms in the world are its floor when
none is given."""

from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.mechanism import Mechanism

PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)
CAPSULE, CYLINDER = int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_CYLINDER)
SPHERE, BOX = int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_BOX)


@dataclass
class CollisionChecker:
    """Contacts of a mechanism's geoms at closed configurations ``qpos``."""

    model: mujoco.MjModel
    data: mujoco.MjData
    weld: np.ndarray  # each geom's weld body
    allowed: set[tuple[int, int]]  # weld-body pairs never counted
    floor_z: float | None

    @classmethod
    def of(cls, mech: Mechanism, home_qpos: np.ndarray, floor_z: float | None) -> CollisionChecker:
        m = copy.deepcopy(mech.model)
        m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        m.geom_contype[:] = 1
        m.geom_conaffinity[:] = 1
        m.body_contype[:] = 1  # the broad phase's per-body masks, compiled from the geoms'
        m.body_conaffinity[:] = 1
        d = mujoco.MjData(m)
        body_weld = m.body_weldid
        weld = body_weld[m.geom_bodyid]
        allowed: set[tuple[int, int]] = set()
        for b in range(1, m.nbody):
            allowed.add(_pair(body_weld[b], body_weld[m.body_parentid[body_weld[b]]]))
        for i in range(m.neq):
            a, b = int(m.eq_obj1id[i]), int(m.eq_obj2id[i])
            if int(m.eq_objtype[i]) == int(mujoco.mjtObj.mjOBJ_SITE):
                a, b = int(m.site_bodyid[a]), int(m.site_bodyid[b])
            allowed.add(_pair(body_weld[a], body_weld[b]))
        planes = [g for g in range(m.ngeom) if m.geom_type[g] == PLANE and weld[g] == 0]
        if floor_z is None and planes:
            floor_z = float(max(m.geom_pos[g][2] for g in planes))
        checker = cls(m, d, weld, allowed, floor_z)
        checker.allowed |= {pair for pair, _ in checker.contacts(home_qpos) if pair}
        return checker

    def contacts(self, qpos: np.ndarray) -> list[tuple[tuple[int, int], tuple[int, int]]]:
        """(weld pair, geom pair) of every contact at ``qpos`` not filtered (module docstring)."""
        m, d = self.model, self.data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        out = []
        for c in d.contact[: d.ncon]:
            g1, g2 = int(c.geom1), int(c.geom2)
            if PLANE in (m.geom_type[g1], m.geom_type[g2]):
                continue  # the floor is checked by height
            pair = _pair(self.weld[g1], self.weld[g2])
            if pair[0] == pair[1] or pair in self.allowed:
                continue
            out.append((pair, (g1, g2)))
        return out

    def problem(self, qpos: np.ndarray) -> str | None:
        """Why the configuration collides (names of the geoms' bodies), or None."""
        hits = self.contacts(qpos)
        m = self.model
        if hits:
            g1, g2 = hits[0][1]
            return f"collision between {_body(m, g1)} and {_body(m, g2)}"
        if self.floor_z is not None:
            low = self.lowest()
            if low is not None and low[0] < self.floor_z:
                return f"{_body(m, low[1])} reaches {low[0] * 1e3:.1f} mm, below the floor"
        return None

    def lowest(self) -> tuple[float, int] | None:
        """The lowest point (z, geom) of the moving bodies' geoms at the last configuration."""
        m, d = self.model, self.data
        best: tuple[float, int] | None = None
        for g in np.flatnonzero(self.weld != 0):
            z = _geom_bottom(m, d, int(g))
            if best is None or z < best[0]:
                best = (z, int(g))
        return best


def _pair(a: int, b: int) -> tuple[int, int]:
    return (int(min(a, b)), int(max(a, b)))


def _body(m: mujoco.MjModel, g: int) -> str:
    b = int(m.geom_bodyid[g])
    return f"body '{mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or b}'"


def _geom_bottom(m: mujoco.MjModel, d: mujoco.MjData, g: int) -> float:
    """Lowest z of a geom: exact for spheres, capsules, cylinders and boxes, its bounding
    sphere otherwise (conservative)."""
    t, size = int(m.geom_type[g]), m.geom_size[g]
    z, rot = d.geom_xpos[g][2], d.geom_xmat[g].reshape(3, 3)
    if t == SPHERE:
        return float(z - size[0])
    if t == CAPSULE:
        return float(z - abs(rot[2, 2]) * size[1] - size[0])
    if t == CYLINDER:
        return float(z - abs(rot[2, 2]) * size[1] - size[0] * np.hypot(rot[2, 0], rot[2, 1]))
    if t == BOX:
        return float(z - np.sum(np.abs(rot[2]) * size[:3]))
    return float(z - m.geom_rbound[g])
