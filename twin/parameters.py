"""Named parameters of an MJCF model: injection in memory and their screw motions.

A parameter is one scalar deviation from the nominal MJCF, of one of five kinds:

* ``body_pos``: the body's origin moves by ``value * axis``, axis in the *parent* frame;
* ``body_rot``: the body frame turns by ``value`` about ``axis`` (parent frame) at its origin;
  several rotations of one body compose as one rotation vector ``w = sum(axis_k v_k)``;
* ``site_pos``: the site moves by ``value * axis``, axis in its body's frame;
* ``joint_zero``: an encoder offset, the joint's true value is the commanded one + ``value``;
* ``actuator_gain``: a scale error of an actuator (element: the actuator's name), ``g``: the
  joint takes ``q0 + (c - q0)(1 + g)`` for the command ``c``, ``q0`` its zero (ppm in files).
* ``joint_compliance``: an actuator that yields to its static gravity load (element: the
  actuator's name): ``q = c - k tau(q)``, ``tau`` the load at the pose of the model's own
  masses plus ``payload_kg`` at the tool site (without it, of 1 kg there alone, ``k`` per kg:
  twin.parameter_kinds); the calibration model computes the loads (calib.fit.joint_compliance).
* the offset kinds (``periodic_error``, ``backlash``, ``drift``, ``thermal_growth``,
  ``thermal_expansion``; element: the actuator's name): the joint value plus ``v phi`` with
  ``phi`` of the command and of the state at the reading, shaped by the parameter's
  ``constants`` (period, phase, time constant, clock, origin: twin.offset_kinds).

The first four are geometry; the others act on the commands, not on the model:
injection leaves it out, its screw is zero and it moves no site at a given configuration (its
identification columns come from the calibration model, which maps commands to joint values
through it). The Jacobians of twin.kinematics.sensitivity and twin.kinematics.sensitivity_batch
refuse it.

Values are SI (metres, radians, gains as plain numbers, compliances in rad/(N m) or m/N).
Injection edits ``body_pos``, ``body_quat``, ``site_pos``, ``qpos0`` of a copy of the nominal
model and calls ``mj_setConst`` (without it, sites compiled at a body origin ignore later
edits). Each parameter also has a *screw* at the current configuration: a world translation
``t``, a world rotation ``w`` about point ``o``, so that a point ``p`` carried by it moves by
``t + w x (p - o)`` and its frame turns by ``w``.
"""

from __future__ import annotations

import copy
import difflib
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.exceptions import ParameterError
from twin.offset_kinds import OFFSET_KINDS, check_constants, check_joint
from twin.parameter_elements import actuated_joint, element_id
from twin.parameter_kinds import (
    ACTUATION_KINDS,
    COMPLIANCE,
    GAIN,
    KINDS,
    check_payload,
    display_units,
    from_display,
    si_units,
    to_display,
)
from twin.rotations import quat_from_rotvec, quat_multiply, skew

SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)
HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)


@dataclass(frozen=True)
class Parameter:
    """One named scalar deviation from the nominal model."""

    name: str
    kind: str
    element: str
    axis: tuple[float, float, float] = (0.0, 0.0, 0.0)
    payload_kg: float | None = None  # a joint_compliance's tool payload (None: per kg)
    # an offset kind's constants, (key, value) pairs (twin.offset_kinds.CONSTANTS); a dict
    # is accepted and stored sorted
    constants: tuple[tuple[str, float | str], ...] = ()

    @property
    def constants_dict(self) -> dict[str, float | str]:
        return dict(self.constants)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ParameterError(f"parameter name must be a non-empty string, got {self.name!r}")
        for field in ("kind", "element"):
            value = getattr(self, field)
            if not isinstance(value, str) or not value:
                raise ParameterError(
                    f"parameter '{self.name}': {field} must be a non-empty string, got {value!r}"
                )
        if self.kind not in KINDS:
            near = difflib.get_close_matches(self.kind, KINDS, n=1)
            hint = f" (did you mean '{near[0]}'?)" if near else ""
            raise ParameterError(
                f"parameter '{self.name}': kind '{self.kind}' not in {KINDS}{hint}"
            )
        try:
            axis = tuple(self.axis)
        except TypeError:
            raise ParameterError(
                f"parameter '{self.name}': axis {self.axis!r} must be 3 numbers"
            ) from None
        if len(axis) != 3:
            raise ParameterError(
                f"parameter '{self.name}': axis {self.axis} must have 3 components"
            )
        if any(
            isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.number))
            for x in axis
        ):
            raise ParameterError(f"parameter '{self.name}': axis {self.axis!r} must be 3 numbers")
        check_payload(self.name, self.kind, self.payload_kg)
        raw = self.constants.items() if isinstance(self.constants, dict) else self.constants
        try:
            consts = tuple(sorted((str(k), v) for k, v in raw))
        except (TypeError, ValueError):
            raise ParameterError(
                f"parameter '{self.name}': constants {raw!r} are no pairs"
            ) from None
        object.__setattr__(self, "constants", consts)
        check_constants(self.name, self.kind, dict(consts))
        if self.kind not in ("joint_zero", *ACTUATION_KINDS):
            n = float(np.linalg.norm(self.axis))
            if not np.isclose(n, 1.0, atol=1e-9):
                raise ParameterError(
                    f"parameter '{self.name}': axis {self.axis} is not a unit vector"
                )


class ParameterSet:
    """An ordered set of parameters bound to one model's element ids."""

    def __init__(self, parameters: Sequence[Parameter], model: mujoco.MjModel) -> None:
        self.parameters = tuple(parameters)
        names = [p.name for p in self.parameters]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ParameterError(f"duplicate parameter names: {dup}")
        self.names: tuple[str, ...] = tuple(names)
        n = len(self.parameters)
        self.kind = np.array([KINDS.index(p.kind) for p in self.parameters], dtype=int)
        self.axis = np.array([p.axis for p in self.parameters], dtype=float).reshape(n, 3)
        self.element = np.zeros(n, dtype=int)
        # body whose subtree the parameter moves (a gain: its joint's body; it moves none)
        self.body = np.zeros(n, dtype=int)
        self.is_angle = np.zeros(n, dtype=bool)
        self.is_gain = self.kind == GAIN
        self.is_compliance = self.kind == COMPLIANCE
        self.is_offset = np.isin(self.kind, [KINDS.index(k) for k in OFFSET_KINDS])
        self.is_geometric = ~(self.is_gain | self.is_compliance | self.is_offset)
        # a compliance's payload (kg; NaN: per kg of payload) and whether its joint turns
        self.payload_kg = np.array(
            [np.nan if p.payload_kg is None else float(p.payload_kg) for p in self.parameters]
        )
        self.turns = np.zeros(n, dtype=bool)
        for k, p in enumerate(self.parameters):
            i = element_id(model, p)
            self.element[k] = i
            if p.kind in ACTUATION_KINDS:
                j = actuated_joint(model, p, i)
                self.body[k] = model.jnt_bodyid[j]
                self.turns[k] = int(model.jnt_type[j]) == HINGE
                check_joint(p.name, p.kind, p.constants_dict, bool(self.turns[k]))
            elif p.kind == "site_pos":
                self.body[k] = model.site_bodyid[i]
            elif p.kind == "joint_zero":
                jt = int(model.jnt_type[i])
                if jt not in (HINGE, SLIDE):
                    raise ParameterError(f"parameter '{p.name}': joint '{p.element}' is not 1-DOF")
                self.body[k] = model.jnt_bodyid[i]
                self.is_angle[k] = jt == HINGE
            else:
                if i == 0:
                    raise ParameterError(f"parameter '{p.name}': the world body cannot move")
                self.body[k] = i
                self.is_angle[k] = p.kind == "body_rot"
        # subtree[k, b]: body b is the parameter's body or one of its descendants
        parent = model.body_parentid
        self.subtree = np.zeros((n, model.nbody), dtype=bool)
        for b in range(model.nbody):
            chain = set()
            a = b
            while True:
                chain.add(a)
                if a == 0:
                    break
                a = parent[a]
            for k in range(n):
                self.subtree[k, b] = self.body[k] in chain and bool(self.is_geometric[k])
        self._rot_bodies = sorted({int(self.body[k]) for k in range(n) if self.kind[k] == 1})
        self._index_kinds()
        self._local = threading.local()

    def _index_kinds(self) -> None:
        """The parameters of each kind, in order, and the body each rotation turns (as an
        index into ``_rot_bodies``): injection works on these arrays, not parameter by one."""
        self._of_kind = [np.flatnonzero(self.kind == i) for i in range(len(KINDS))]
        self._rot_slot = np.searchsorted(self._rot_bodies, self.body[self._of_kind[1]])

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        del state["_local"]  # per-thread scratch: not for copies or other processes
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        if "is_gain" not in state:  # pickled before the gain kind
            self.is_gain = self.kind == GAIN
        if "is_compliance" not in state:  # pickled before the compliance kind
            self.is_compliance = np.zeros(len(self.kind), dtype=bool)
            self.is_geometric = ~self.is_gain
            self.payload_kg = np.full(len(self.kind), np.nan)
            self.turns = np.zeros(len(self.kind), dtype=bool)
        if "is_offset" not in state:  # pickled before the offset kinds
            self.is_offset = np.zeros(len(self.kind), dtype=bool)
        if len(state.get("_of_kind", ())) != len(KINDS):  # pickled before the kinds were indexed
            self._index_kinds()
        self._local = threading.local()

    def __len__(self) -> int:
        return len(self.parameters)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise ParameterError(f"unknown parameter '{name}'") from None

    @property
    def has_gains(self) -> bool:
        """Whether any parameter is an actuator gain (not geometry)."""
        return bool(np.any(self.is_gain))

    @property
    def has_compliance(self) -> bool:
        """Whether any parameter is a joint compliance (not geometry)."""
        return bool(np.any(self.is_compliance))

    @property
    def is_geometry(self) -> bool:
        """Whether every parameter is geometry (no gain, no compliance)."""
        return bool(np.all(self.is_geometric))

    def units(self) -> list[str]:
        """SI unit of each parameter (twin.parameter_kinds.si_units)."""
        return si_units(self)

    def display_units(self) -> list[str]:
        """Unit of each parameter in files, results and printouts (mm, deg, ppm, a
        compliance's deg/(kN m) or mm/kN; twin.parameter_kinds)."""
        return display_units(self)

    def to_display(self, values: np.ndarray) -> np.ndarray:
        """SI -> the display units, per parameter."""
        return to_display(self, values)

    def from_display(self, values: Iterable[float]) -> np.ndarray:
        """The display units -> SI, per parameter."""
        return from_display(self, values)

    # ----------------------------------------------------------------- injection
    def rotation_vectors(self, values: np.ndarray) -> dict[int, np.ndarray]:
        """Per rotated body, the rotation vector w = sum(axis_k v_k) (parent frame)."""
        w = self._rotation_vector_array(values)
        return {b: w[i] for i, b in enumerate(self._rot_bodies)}

    def _rotation_vector_array(self, values: np.ndarray) -> np.ndarray:
        """(len(_rot_bodies), 3): the rotation vectors, each summed in parameter order."""
        k1 = self._of_kind[1]
        w = np.zeros((len(self._rot_bodies), 3))
        np.add.at(w, self._rot_slot, self.axis[k1] * np.asarray(values)[k1, None])
        return w

    def inject(self, nominal: mujoco.MjModel, values: np.ndarray) -> mujoco.MjModel:
        """A copy of ``nominal`` with the deviations ``values`` (SI) applied."""
        values = np.asarray(values, dtype=float)
        if values.shape != (len(self),):
            raise ParameterError(f"expected {len(self)} parameter values, got shape {values.shape}")
        if not np.all(np.isfinite(values)):
            bad = [self.names[k] for k in np.flatnonzero(~np.isfinite(values))]
            raise ParameterError(f"non-finite parameter values for {bad}")
        model = copy.deepcopy(nominal)
        # several parameters of one element add up in parameter order (np.add.at is
        # unbuffered and sequential: the same sums as one parameter after the other)
        k0, k2, k3 = (self._of_kind[KINDS.index(k)] for k in ("body_pos", "site_pos", "joint_zero"))
        np.add.at(model.body_pos, self.element[k0], self.axis[k0] * values[k0, None])
        np.add.at(model.site_pos, self.element[k2], self.axis[k2] * values[k2, None])
        np.add.at(model.qpos0, model.jnt_qposadr[self.element[k3]], -values[k3])
        if self._rot_bodies:
            b = np.array(self._rot_bodies)
            w = self._rotation_vector_array(values)
            model.body_quat[b] = quat_multiply(quat_from_rotvec(w), nominal.body_quat[b])
        mujoco.mj_setConst(model, self._scratch_data(nominal))
        return model

    def _scratch_data(self, nominal: mujoco.MjModel) -> mujoco.MjData:
        """An MjData of ``nominal``'s sizes for mj_setConst, which resets and overwrites what
        it uses (kept per thread: an estimator injects values at every evaluation)."""
        held = getattr(self._local, "scratch", None)
        if held is None or held[0] is not nominal:
            held = (nominal, mujoco.MjData(nominal))
            self._local.scratch = held
        return held[1]

    # ----------------------------------------------------------------- screws
    def screws(
        self, model: mujoco.MjModel, data: mujoco.MjData, values: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World translation t (n,3), rotation w (n,3) and pivot o (n,3) of each parameter.

        ``data`` must hold kinematics (``mj_kinematics``) of ``model`` with ``values`` injected.
        """
        n = len(self)
        t = np.zeros((n, 3))
        w = np.zeros((n, 3))
        o = np.zeros((n, 3))
        xmat = data.xmat.reshape(-1, 3, 3)
        rotated = self._rotated_axes(values)
        for k in range(n):
            kind, i = self.kind[k], self.element[k]
            if kind == 0:
                t[k] = xmat[model.body_parentid[i]] @ self.axis[k]
            elif kind == 1:
                par = model.body_parentid[i]
                w[k] = xmat[par] @ rotated[k]
                o[k] = data.xpos[par] + xmat[par] @ model.body_pos[i]
            elif kind == 2:
                t[k] = xmat[model.site_bodyid[i]] @ self.axis[k]
            elif not self.is_geometric[k]:  # no motion at a given configuration
                continue
            elif self.is_angle[k]:
                w[k] = data.xaxis[i]
                o[k] = data.xanchor[i]
            else:
                t[k] = data.xaxis[i]
        return t, w, o

    def _rotated_axes(self, values: np.ndarray) -> dict[int, np.ndarray]:
        """J_l(w) axis of each body-rotation parameter k at ``values``, in the parent's frame:
        the same for every pose, so kept (per thread) for the last ``values`` seen; a
        per-pose Jacobian over thousands of poses otherwise spent half its time on it."""
        values = np.asarray(values, dtype=float)
        key = values.tobytes()
        held = getattr(self._local, "rotated", None)
        if held is None or held[0] != key:
            rotvecs = self.rotation_vectors(values)
            rotated = {
                int(k): left_jacobian_so3(rotvecs[int(self.element[k])]) @ self.axis[k]
                for k in np.flatnonzero(self.kind == 1)
            }
            held = (key, rotated)
            self._local.rotated = held
        return held[1]

    def screws_soa(
        self,
        model: mujoco.MjModel,
        xpos: np.ndarray,
        xmat: np.ndarray,
        xanchor: np.ndarray,
        xaxis: np.ndarray,
        values: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`screws` for N poses at once, each (3, n, N), from frames with the poses
        last: ``xpos`` (3, nbody, N), ``xmat`` (3, 3, nbody, N), ``xanchor`` and ``xaxis``
        (3, njnt, N) (twin.kinematics.tree.TreeFrames)."""
        n_pose, n = xpos.shape[-1], len(self)
        t, w, o = (np.zeros((3, n, n_pose)) for _ in range(3))
        kind, el, axis = self.kind, self.element, self.axis
        k0 = np.flatnonzero(kind == 0)
        t[:, k0] = np.einsum("ijkn,kj->ikn", xmat[:, :, model.body_parentid[el[k0]]], axis[k0])
        k1 = np.flatnonzero(kind == 1)
        if k1.size:
            rotated = self._rotated_axes(values)
            local = np.array([rotated[int(k)] for k in k1]).reshape(-1, 3)
            par = model.body_parentid[el[k1]]
            w[:, k1] = np.einsum("ijkn,kj->ikn", xmat[:, :, par], local)
            o[:, k1] = xpos[:, par] + np.einsum(
                "ijkn,kj->ikn", xmat[:, :, par], model.body_pos[el[k1]]
            )
        k2 = np.flatnonzero(kind == 2)
        t[:, k2] = np.einsum("ijkn,kj->ikn", xmat[:, :, model.site_bodyid[el[k2]]], axis[k2])
        k3 = np.flatnonzero(kind == 3)
        hinge, slide = k3[self.is_angle[k3]], k3[~self.is_angle[k3]]
        w[:, hinge] = xaxis[:, el[hinge]]
        o[:, hinge] = xanchor[:, el[hinge]]
        t[:, slide] = xaxis[:, el[slide]]
        return t, w, o

    def site_affected(self, model: mujoco.MjModel, sites: np.ndarray) -> np.ndarray:
        """(S, n) bool: the parameter moves the site (a body parameter every site of its
        subtree, a site parameter its own site only)."""
        sites = np.asarray(sites, dtype=int)
        affected = self.subtree[:, model.site_bodyid[sites]].T.copy()  # (S, n)
        site_kind = self.kind == 2
        affected[:, site_kind] = sites[:, None] == self.element[site_kind][None, :]
        return affected

    def site_derivatives(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        values: np.ndarray,
        sites: np.ndarray,
        screws: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Explicit d(site position)/d(param) and d(site rotation)/d(param), each (S, 3, n)."""
        t, w, o = screws if screws is not None else self.screws(model, data, values)
        sites = np.asarray(sites, dtype=int)
        p = data.site_xpos[sites]  # (S,3)
        affected = self.site_affected(model, sites)
        dp = t[None, :, :] + np.cross(w[None, :, :], p[:, None, :] - o[None, :, :])  # (S,n,3)
        dp *= affected[:, :, None]
        dw = w[None, :, :] * affected[:, :, None]
        return dp.transpose(0, 2, 1), dw.transpose(0, 2, 1)


def require_geometry(params: ParameterSet, what: str) -> None:
    """Raise ParameterError if ``params`` holds actuator gains or joint compliances: ``what``
    (a Jacobian of the geometry at given joint values) has no column for them; the
    calibration model adds them (it maps commands to joint values through them)."""
    if not params.is_geometry:
        names = [params.names[k] for k in np.flatnonzero(~params.is_geometric)]
        raise ParameterError(
            f"{what} takes geometric parameters only; {names[:3]} are actuator gains or joint "
            "compliances, which act through the commands (calib.fit.model.CalibrationModel adds "
            "their columns)"
        )


def left_jacobian_so3(w: np.ndarray) -> np.ndarray:
    """d exp(w) = [J_l(w) dw]x exp(w): the left Jacobian of SO(3)."""
    theta = float(np.linalg.norm(w))
    k = skew(w)
    if theta < 1e-8:
        return np.eye(3) + 0.5 * k + k @ k / 6.0
    return (
        np.eye(3)
        + (1 - np.cos(theta)) / theta**2 * k
        + (theta - np.sin(theta)) / theta**3 * (k @ k)
    )
