"""One object wrapping a MuJoCo model of a closed-chain machine, for twin and calib alike.

What it reads from the MJCF (and refuses to guess):
* actuators: every ``<actuator>`` entry drives one slide or hinge joint; its name is the
  actuator's name in datasets; the joint's value is the commanded value (metres/radians);
* closures: every ``<equality>`` of type ``connect`` or ``weld`` between two *sites*
  (a body-based connect stores its anchor at compile time and would absorb injected errors);
* targets: the sites named ``target_*`` (laser-tracker reflectors on the tool);
* tool: the site ``tool``, whose pose inverse kinematics commands;
* workspace: optional ``<numeric name="workspace_min|workspace_max">`` (x, y, z, rx, ry, rz);
* home: keyframe ``home`` (start of every closure solve, which keeps one assembly branch).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from twin.exceptions import ModelError
from twin.rotations import matrix_from_quat

TARGET_PREFIX = "target_"
SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
TOOL_SITE = "tool"


@dataclass(frozen=True)
class Closure:
    """A site-based loop closure: ``connect`` (3 equations) or ``weld`` (6)."""

    name: str
    kind: str
    site_a: int
    site_b: int

    @property
    def size(self) -> int:
        return 6 if self.kind == "weld" else 3


class Mechanism:
    """A MuJoCo model plus the names calibration needs. Pure kinematics lives elsewhere."""

    def __init__(self, model: mujoco.MjModel, name: str | None = None) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.name = name or model.names[: model.names.find(b"\0")].decode() or "model"
        self._read_actuators()
        self._read_closures()
        self._read_targets()
        self._read_home()
        self._read_workspace()

    # ----------------------------------------------------------------- construction
    @classmethod
    def from_xml(cls, path: str | Path) -> Mechanism:
        path = Path(path)
        if not path.is_file():
            raise ModelError(f"MJCF file not found: {path}")
        try:
            model = mujoco.MjModel.from_xml_path(str(path))
        except ValueError as exc:
            raise ModelError(f"MuJoCo could not compile {path}: {exc}") from exc
        return cls(model, name=None)

    @classmethod
    def from_xml_string(cls, xml: str) -> Mechanism:
        try:
            model = mujoco.MjModel.from_xml_string(xml)
        except ValueError as exc:
            raise ModelError(f"MuJoCo could not compile the MJCF string: {exc}") from exc
        return cls(model)

    def copy(self) -> Mechanism:
        """An independent mechanism (own MjModel and MjData)."""
        return Mechanism(copy.deepcopy(self.model), name=self.name)

    # ----------------------------------------------------------------- reading names
    def _read_actuators(self) -> None:
        m = self.model
        if m.nu == 0:
            raise ModelError(f"model '{self.name}' has no <actuator>: nothing to command")
        names, joints = [], []
        for i in range(m.nu):
            if int(m.actuator_trntype[i]) != int(mujoco.mjtTrn.mjTRN_JOINT):
                raise ModelError(f"actuator {i} of '{self.name}' does not drive a joint")
            j = int(m.actuator_trnid[i, 0])
            if int(m.jnt_type[j]) not in (SLIDE, HINGE):
                raise ModelError(f"actuator {i} drives joint {j}, which is not slide or hinge")
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i)
            if not name:
                raise ModelError(f"actuator {i} of '{self.name}' has no name")
            names.append(name)
            joints.append(j)
        self.actuator_names: tuple[str, ...] = tuple(names)
        self.actuator_joints = np.array(joints, dtype=int)
        self.actuator_qpos = m.jnt_qposadr[self.actuator_joints].copy()
        self.actuator_dofs = m.jnt_dofadr[self.actuator_joints].copy()
        self.actuator_is_slide = m.jnt_type[self.actuator_joints] == SLIDE
        limited = m.jnt_limited[self.actuator_joints].astype(bool)
        rng = m.jnt_range[self.actuator_joints].copy()
        rng[~limited] = [-np.inf, np.inf]
        self.actuator_range = rng

    def _read_closures(self) -> None:
        m = self.model
        closures = []
        for i in range(m.neq):
            kind = {
                int(mujoco.mjtEq.mjEQ_CONNECT): "connect",
                int(mujoco.mjtEq.mjEQ_WELD): "weld",
            }.get(int(m.eq_type[i]))
            if kind is None:
                continue
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_EQUALITY, i) or f"equality{i}"
            if int(m.eq_objtype[i]) != int(mujoco.mjtObj.mjOBJ_SITE):
                raise ModelError(
                    f"closure '{name}' is body-based; use site1/site2: a body-based {kind} "
                    "stores its anchor at compile time and silently absorbs injected errors"
                )
            closures.append(Closure(name, kind, int(m.eq_obj1id[i]), int(m.eq_obj2id[i])))
        if not closures:
            raise ModelError(f"model '{self.name}' has no site-based connect/weld closure")
        self.closures: tuple[Closure, ...] = tuple(closures)
        self.n_closure = sum(c.size for c in closures)

    def _read_targets(self) -> None:
        m = self.model
        ids, names = [], []
        for i in range(m.nsite):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, i) or ""
            if name.startswith(TARGET_PREFIX):
                ids.append(i)
                names.append(name)
        if not ids:
            raise ModelError(
                f"model '{self.name}' has no tracker target sites ('{TARGET_PREFIX}*')"
            )
        self.target_names: tuple[str, ...] = tuple(names)
        self.target_sites = np.array(ids, dtype=int)
        tool = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, TOOL_SITE)
        if tool < 0:
            raise ModelError(f"model '{self.name}' has no '{TOOL_SITE}' site (the commanded frame)")
        self.tool_site = int(tool)
        self.tool_body = int(m.site_bodyid[tool])

    def _read_home(self) -> None:
        m = self.model
        key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home")
        self.home_qpos = (m.key_qpos[key] if key >= 0 else m.qpos0).copy()

    def _read_workspace(self) -> None:
        self.workspace_min = self._numeric("workspace_min", 6)
        self.workspace_max = self._numeric("workspace_max", 6)

    def _numeric(self, name: str, size: int) -> np.ndarray | None:
        m = self.model
        i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, name)
        if i < 0:
            return None
        adr, n = m.numeric_adr[i], m.numeric_size[i]
        if n != size:
            raise ModelError(f"<numeric name='{name}'> must hold {size} values, has {n}")
        return m.numeric_data[adr : adr + n].copy()

    # ----------------------------------------------------------------- helpers
    @property
    def n_actuators(self) -> int:
        return len(self.actuator_names)

    @property
    def n_targets(self) -> int:
        return len(self.target_names)

    def free_dofs(self) -> np.ndarray:
        """Degrees of freedom solved for in forward kinematics (all but the actuated)."""
        mask = np.ones(self.model.nv, dtype=bool)
        mask[self.actuator_dofs] = False
        return np.flatnonzero(mask)

    def target_local(self) -> np.ndarray:
        """Target positions in the tool frame (T, 3); targets must sit on the tool's body."""
        m = self.model
        bodies = m.site_bodyid[self.target_sites]
        if np.any(bodies != self.tool_body):
            raise ModelError("tracker targets must be on the same body as the 'tool' site")
        r_tool = matrix_from_quat(m.site_quat[self.tool_site])
        return (m.site_pos[self.target_sites] - m.site_pos[self.tool_site]) @ r_tool

    def site_id(self, name: str) -> int:
        i = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, name)
        if i < 0:
            raise ModelError(f"model '{self.name}' has no site '{name}'")
        return int(i)
