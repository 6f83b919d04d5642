"""Actuator gains in the calibration model: commands to joint values, and their columns.

An ``actuator_gain`` parameter ``g`` (twin.parameters) scales an actuator's travel about its
joint's zero ``q0``, the ``qpos0`` of the model with the geometric values injected (an
injected joint zero moves it): for the command ``c`` the joint takes

    q = q0 + (c - q0)(1 + g),          so          c = q0 + (q - q0) / (1 + g),

the gains of one actuator adding up. The geometry's Jacobian (twin.kinematics.sensitivity_batch) holds
the joint values; the gains enter through them, so with ``J_a`` the column of actuator
``a``'s joint (a joint zero of it moves the targets as its joint value does:
twin.kinematics.inverse_batch.actuator_joint_parameters):

* a gain's column is ``J_a (c_a - q0_a)``, per pose;
* a joint zero of a gained actuator's joint also moves ``q0``: the joint's travel from the
  injected zero is ``(c - q0)(1 + g)``, so its column is ``(1 + g_a)`` times the geometric one.

:class:`ColumnPlan` asks the twin for the geometric columns and the actuators' joint columns
in one pass and assembles these; without gains it is the plain selection of columns.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from twin.exceptions import ParameterError
from twin.kinematics.inverse_batch import actuator_joint_parameters
from twin.mechanism import Mechanism
from twin.parameters import KINDS, Parameter, ParameterSet

JOINT_ZERO = KINDS.index("joint_zero")
BODY_ROT = KINDS.index("body_rot")


def gained_actuators(params: ParameterSet, mech: Mechanism) -> np.ndarray:
    """The actuator (command column of ``mech``) each parameter's gain scales, -1 for a
    parameter that is not a gain (n,)."""
    out = np.full(len(params), -1, dtype=int)
    for k in np.flatnonzero(params.is_gain):
        name = mujoco.mj_id2name(mech.model, mujoco.mjtObj.mjOBJ_ACTUATOR, int(params.element[k]))
        out[k] = mech.actuator_names.index(name)
    return out


def zeroed_actuators(params: ParameterSet, mech: Mechanism) -> np.ndarray:
    """The actuator whose joint each parameter's joint zero offsets, -1 for a parameter that
    is not a joint zero of an actuated joint (n,)."""
    joints = list(mech.actuator_joints)
    return np.array(
        [
            joints.index(int(params.element[k]))
            if params.kind[k] == JOINT_ZERO and int(params.element[k]) in joints
            else -1
            for k in range(len(params))
        ],
        dtype=int,
    )


@dataclass(frozen=True)
class GainMap:
    """The gain parameters of a model's parameter set and the actuators they scale."""

    index: np.ndarray  # (G,) the parameters that are gains
    actuator: np.ndarray  # (G,) the actuator each scales
    names: tuple[str, ...]  # the actuators' names, for errors

    @classmethod
    def of(cls, params: ParameterSet, mech: Mechanism) -> GainMap | None:
        """The gains of ``params`` on ``mech``; None if it has none."""
        if not params.has_gains:
            return None
        index = np.flatnonzero(params.is_gain)
        return cls(index, gained_actuators(params, mech)[index], mech.actuator_names)

    def gains(self, values: np.ndarray) -> np.ndarray:
        """g per actuator (A,), the sum of its gain parameters' values (0 where none)."""
        g = np.zeros(len(self.names))
        np.add.at(g, self.actuator, np.asarray(values, dtype=float)[self.index])
        return g

    def scale(self, values: np.ndarray) -> np.ndarray:
        """1 + g per actuator (A,); a clear error where it is not positive."""
        s = 1.0 + self.gains(values)
        if not np.all(s > 0):
            a = int(np.flatnonzero(~(s > 0))[0])
            raise ParameterError(
                f"actuator '{self.names[a]}': a gain of {(s[a] - 1.0) * 1e6:.6g} ppm leaves it "
                "no travel (1 + gain must be positive)"
            )
        return s

    def joints(self, values: np.ndarray, commands: np.ndarray, zero: np.ndarray) -> np.ndarray:
        """The joint values (N, A) the commands (N, A) give; ``zero`` (A,) the joints' zeros.
        An actuator without gain keeps its command exactly."""
        c = np.asarray(commands, dtype=float)
        g = self.gains(values)
        return np.where(g != 0.0, zero + (c - zero) * self.scale(values), c)

    def commands(self, values: np.ndarray, joints: np.ndarray, zero: np.ndarray) -> np.ndarray:
        """The commands (N, A) that give the joint values (N, A): :meth:`joints` inverted."""
        q = np.asarray(joints, dtype=float)
        g = self.gains(values)
        return np.where(g != 0.0, zero + (q - zero) / self.scale(values), q)


@dataclass(frozen=True)
class ColumnPlan:
    """Chosen columns of a model's Jacobian (gains among them or not) beside the columns of
    ``extra`` parameters at zero, from one geometric Jacobian of the twin.

    ``params`` is what the twin differentiates: the chosen geometric parameters with their
    companions (a body's rotations compose into one rotation vector, which enters the screw
    of each), then, with gains, one joint parameter per actuator, then the extra geometry."""

    params: ParameterSet
    index: np.ndarray  # the model's parameter behind each of the first len(index) of params
    source: np.ndarray  # (m,) the twin's column behind each returned column
    actuator: np.ndarray  # (m,) the actuator a gain column or a scaled joint zero's is of, -1
    is_gain: np.ndarray  # (m,) a gain's column (else, with an actuator, a joint zero's)
    gains: GainMap | None  # the model's gains
    actuator_qpos: np.ndarray  # (A,)

    @classmethod
    def of(
        cls,
        params: ParameterSet,
        mech: Mechanism,
        columns: np.ndarray,
        extra: ParameterSet | None = None,
    ) -> ColumnPlan:
        """The plan for ``params``' ``columns`` (in that order) then every ``extra`` one."""
        cols = np.asarray(columns, dtype=int)
        extra_list = list(extra.parameters) if extra is not None else []
        extra_gain = extra.is_gain if extra is not None else np.zeros(0, dtype=bool)
        geo = cols[~params.is_gain[cols]]
        rot = params.kind == BODY_ROT
        turned = np.unique(params.body[geo[rot[geo]]])
        index = np.union1d(geo, np.flatnonzero(rot & np.isin(params.body, turned)))
        gains = GainMap.of(params, mech)
        with_joints = gains is not None or bool(np.any(extra_gain))
        joints = list(actuator_joint_parameters(mech).parameters) if with_joints else []
        # the added ones renamed apart (a name of theirs may also be one of the model's)
        added = [Parameter(f"gain:{p.name}", p.kind, p.element, p.axis) for p in joints] + [
            Parameter(f"extra:{p.name}", p.kind, p.element, p.axis)
            for p, g in zip(extra_list, extra_gain, strict=True)
            if not g
        ]
        chosen = ParameterSet([params.parameters[k] for k in index] + added, mech.model)
        n_idx, n_act = len(index), len(joints)
        # each returned column: its source, and the actuator whose gain enters it
        model_act = gained_actuators(params, mech)
        model_zero = (
            zeroed_actuators(params, mech) if gains is not None else np.full(len(params), -1)
        )
        source, actuator, is_gain = [], [], []
        for c in cols:
            g = bool(params.is_gain[c])
            source.append(n_idx + model_act[c] if g else int(np.searchsorted(index, c)))
            actuator.append(model_act[c] if g else model_zero[c])
            is_gain.append(g)
        if extra is not None:
            extra_act = gained_actuators(extra, mech)
            extra_zero = (
                zeroed_actuators(extra, mech) if gains is not None else np.full(len(extra), -1)
            )
            k_geo = n_idx + n_act
            for e in range(len(extra)):
                g = bool(extra_gain[e])
                source.append(n_idx + extra_act[e] if g else k_geo)
                k_geo += 0 if g else 1
                actuator.append(extra_act[e] if g else extra_zero[e])
                is_gain.append(g)
        return cls(
            chosen,
            index,
            np.array(source, dtype=int),
            np.array(actuator, dtype=int),
            np.array(is_gain, dtype=bool),
            gains,
            np.asarray(mech.actuator_qpos, dtype=int),
        )

    def values_for(self, values: np.ndarray) -> np.ndarray:
        """The values of ``params`` at the model's ``values``: the added ones at zero."""
        values = np.asarray(values, dtype=float)
        return np.concatenate([values[self.index], np.zeros(len(self.params) - len(self.index))])

    def assemble(
        self, jac: np.ndarray, values: np.ndarray, qpos: np.ndarray, zero: np.ndarray
    ) -> np.ndarray:
        """The returned columns (N, rows, m) from the twin's Jacobian ``jac`` (N, rows, n) of
        ``params`` at the closed configurations ``qpos`` (N, nq) of the model at ``values``,
        whose actuated joints' zeros are ``zero`` (A,)."""
        out = jac[:, :, self.source]
        act = self.actuator >= 0
        if not np.any(act):
            return out
        g = self.gains.gains(values) if self.gains is not None else np.zeros(len(zero))
        gain_cols = np.flatnonzero(self.is_gain)
        if gain_cols.size:
            travel = (qpos[:, self.actuator_qpos] - zero) / (1.0 + g)  # c - q0, (N, A)
            out[:, :, gain_cols] *= travel[:, None, self.actuator[gain_cols]]
        zero_cols = np.flatnonzero(act & ~self.is_gain)
        if zero_cols.size:
            out[:, :, zero_cols] *= 1.0 + g[self.actuator[zero_cols]]
        return out
