"""One object wrapping a MuJoCo model of a machine, for twin and calib alike.

Serial, parallel and hybrid machines are one kind of thing here: a serial chain is a
mechanism with zero closure equations (every joint actuated, forward kinematics direct), a
parallel or hybrid one has closures that fix its passive joints. What it reads from the
MJCF (and refuses to guess):
* actuators: every ``<actuator>`` entry drives one slide or hinge joint; its name is the
  actuator's name in datasets; the joint's value is the commanded value (metres/radians)
  divided by the actuator's ``gear`` (MuJoCo's default 1: the command itself). The command is
  the set point of the actuator's length ``gear * qpos``, where a MuJoCo ``<position>`` servo
  settles; a calibrated model holds an actuator's gain there (calib export). The strokes are
  the joint's range in commands (``gear`` times it);
* closures: every ``<equality>`` of type ``connect`` or ``weld`` between two *sites*
  (a body-based connect stores its anchor at compile time and would absorb injected errors);
* targets: the sites named ``target_*`` (laser-tracker reflectors on the tool);
* tool: the site ``tool``, whose pose inverse kinematics commands;
* workspace: optional ``<numeric name="workspace_min|workspace_max">`` (x, y, z, rx, ry, rz);
* home: keyframe ``home`` (start of every closure solve, which keeps one assembly branch).

Kinematics needs no inertia. MuJoCo refuses moving bodies without mass, so a file that
declares none is compiled with MuJoCo's own ``boundmass``/``boundinertia`` (1 g, 1e-6
kg m^2) and ``masses_defaulted`` says so: a gravity effect on such masses is meaningless.
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
BOUND_MASS = 1e-3  # kg, for bodies an MJCF gives no mass (kinematics-only models)
BOUND_INERTIA = 1e-6  # kg m^2
_NO_MASS = "mass and inertia of moving bodies must be larger than mjMINVAL"


def check_actuated(spec: mujoco.MjSpec, where: str) -> None:
    """Refuse a machine model without ``<actuator>`` before compiling it: MuJoCo would name
    only a consequence (a keyframe's ctrl size)."""
    if len(spec.actuators) == 0:
        raise ModelError(
            f"{where}: model '{spec.modelname}' has no <actuator>: nothing to command; "
            "calibration needs one actuator per commanded joint (a dataset's cmd:<name> "
            "columns name them)"
        )


def compile_spec(spec: mujoco.MjSpec, where: str) -> tuple[mujoco.MjModel, bool]:
    """Compile; if MuJoCo refuses bodies without mass, again with bounded defaults.

    Returns the model and whether masses were defaulted."""
    try:
        return spec.compile(), False
    except ValueError as exc:
        if _NO_MASS not in str(exc):
            raise ModelError(f"MuJoCo could not compile {where}: {exc}") from exc
    spec.compiler.boundmass = BOUND_MASS
    spec.compiler.boundinertia = BOUND_INERTIA
    try:
        return spec.compile(), True
    except ValueError as exc:
        raise ModelError(f"MuJoCo could not compile {where}: {exc}") from exc


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

    def __init__(
        self, model: mujoco.MjModel, name: str | None = None, masses_defaulted: bool = False
    ) -> None:
        self.model = model
        self._data: mujoco.MjData | None = None
        self.name = name or model.names[: model.names.find(b"\0")].decode() or "model"
        self.masses_defaulted = bool(masses_defaulted)
        self._read_actuators()
        self._read_closures()
        self._read_targets()
        self._read_home()
        self._read_workspace()
        self._check_degrees_of_freedom()

    # ----------------------------------------------------------------- construction
    @classmethod
    def from_xml(cls, path: str | Path) -> Mechanism:
        path = Path(path)
        if not path.is_file():
            raise ModelError(f"MJCF file not found: {path}")
        try:
            spec = mujoco.MjSpec.from_file(str(path))
        except ValueError as exc:
            raise ModelError(f"MuJoCo could not compile {path}: {exc}") from exc
        check_actuated(spec, str(path))
        model, defaulted = compile_spec(spec, str(path))
        return cls(model, name=None, masses_defaulted=defaulted)

    @classmethod
    def from_xml_string(cls, xml: str) -> Mechanism:
        try:
            spec = mujoco.MjSpec.from_string(xml)
        except ValueError as exc:
            raise ModelError(f"MuJoCo could not compile the MJCF string: {exc}") from exc
        check_actuated(spec, "the MJCF string")
        model, defaulted = compile_spec(spec, "the MJCF string")
        return cls(model, masses_defaulted=defaulted)

    def copy(self) -> Mechanism:
        """An independent mechanism (own MjModel and MjData)."""
        return Mechanism(
            copy.deepcopy(self.model), name=self.name, masses_defaulted=self.masses_defaulted
        )

    def with_model(self, model: mujoco.MjModel) -> Mechanism:
        """The same machine on another model of it (e.g. with errors injected)."""
        return Mechanism(model, name=self.name, masses_defaulted=self.masses_defaulted)

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
        gear = m.actuator_gear[:, 0].copy()
        if not np.all(np.isfinite(gear) & (gear != 0.0)):
            i = int(np.flatnonzero(~(np.isfinite(gear) & (gear != 0.0)))[0])
            raise ModelError(
                f"actuator '{names[i]}' of '{self.name}' has gear {gear[i]!r}: a command must "
                "set its joint (a finite gear other than 0)"
            )
        self.actuator_gear = gear
        limited = m.jnt_limited[self.actuator_joints].astype(bool)
        rng = np.sort(m.jnt_range[self.actuator_joints] * gear[:, None], axis=1)
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

    def _check_degrees_of_freedom(self) -> None:
        """Forward kinematics must be determined: no more free dofs than closure equations."""
        n_free = len(self.free_dofs())
        if n_free > self.n_closure:
            m = self.model
            joints = sorted(
                {
                    mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, int(m.dof_jntid[d]))
                    or f"joint{int(m.dof_jntid[d])}"
                    for d in self.free_dofs()
                }
            )
            what = "has no closure" if self.n_closure == 0 else f"has {self.n_closure} closure"
            raise ModelError(
                f"model '{self.name}' {what} equation(s) for {n_free} unactuated degree(s) of "
                f"freedom (joints {joints}): forward kinematics is undetermined. A serial "
                "chain needs an <actuator> on every joint; a closed chain, site-based "
                "<connect>/<weld> closures that fix its passive joints"
            )

    # ----------------------------------------------------------------- helpers
    @property
    def data(self) -> mujoco.MjData:
        """The model's MjData, made on first use (the batched kinematics never needs it, and
        an estimator makes a mechanism for every parameter value it tries)."""
        if self._data is None:
            self._data = mujoco.MjData(self.model)
        return self._data

    @property
    def is_serial(self) -> bool:
        """No closures: forward kinematics is direct."""
        return self.n_closure == 0

    @property
    def is_geared(self) -> bool:
        """Whether an actuator's joint value differs from its command (a gear other than 1)."""
        return bool(np.any(self.actuator_gear != 1.0))

    def joints_of_commands(self, commands: np.ndarray) -> np.ndarray:
        """The actuated joints' values (..., A) of the commands (..., A): command / gear."""
        c = np.asarray(commands, dtype=float)
        return c / self.actuator_gear if self.is_geared else c

    def commands_of_joints(self, joints: np.ndarray) -> np.ndarray:
        """The commands (..., A) that hold the actuated joints at ``joints`` (..., A)."""
        q = np.asarray(joints, dtype=float)
        return q * self.actuator_gear if self.is_geared else q

    @property
    def home_commands(self) -> np.ndarray:
        """The commands (A,) of the home configuration."""
        return self.commands_of_joints(self.home_qpos[self.actuator_qpos])

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
