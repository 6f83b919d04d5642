"""Actuator gains in the calibration model: commands to joint values, and their columns.

An ``actuator_gain`` parameter ``g`` (twin.parameters) scales an actuator's travel about its
joint's zero ``q0``, the ``qpos0`` of the model with the geometric values injected (an
injected joint zero moves it): for the command ``c`` the joint takes

    q = q0 + (c - q0)(1 + g),          so          c = q0 + (q - q0) / (1 + g),

the gains of one actuator adding up. The geometry's Jacobian (twin.kinematics.sensitivity_batch)
holds
the joint values; the gains enter through them, so with ``J_a`` the column of actuator
``a``'s joint (a joint zero of it moves the targets as its joint value does:
twin.kinematics.inverse_batch.actuator_joint_parameters):

* a gain's column is ``J_a (c_a - q0_a)``, per pose;
* a joint zero of a gained actuator's joint also moves ``q0``: the joint's travel from the
  injected zero is ``(c - q0)(1 + g)``, so its column is ``(1 + g_a)`` times the geometric one.

Joint compliances (calib.fit.joint_compliance) subtract their deflection ``D(q)`` from the joint
value the gain gives: a compliance's column is ``J_a (-L_k)`` per pose (its load at the settled
configuration), and a gain's travel is read from ``q + D``, the joint value before the joint
yields.

:class:`ColumnPlan` asks the twin for the geometric columns and the actuators' joint columns
in one pass and assembles these; without gains or compliances it is the plain selection of
columns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.diagnosis.gravity import GravityLoads
from calib.fit.joint_compliance import ComplianceMap, acting_actuators, load_columns
from calib.fit.kinds import OffsetMap
from twin.exceptions import ParameterError
from twin.kinematics.inverse_batch import actuator_joint_parameters
from twin.mechanism import Mechanism
from twin.parameters import KINDS, Parameter, ParameterSet

JOINT_ZERO = KINDS.index("joint_zero")
BODY_ROT = KINDS.index("body_rot")


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
        return cls(index, acting_actuators(params, mech)[index], mech.actuator_names)

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
    """Chosen columns of a model's Jacobian (gains and compliances among them or not) beside
    the columns of ``extra`` parameters at zero, from one geometric Jacobian of the twin.

    ``params`` is what the twin differentiates: the chosen geometric parameters with their
    companions (a body's rotations compose into one rotation vector, which enters the screw
    of each), then, with gains or compliances, one joint parameter per actuator, then the
    extra geometry."""

    params: ParameterSet
    index: np.ndarray  # the model's parameter behind each of the first len(index) of params
    source: np.ndarray  # (m,) the twin's column behind each returned column
    actuator: np.ndarray  # (m,) the actuator a gain's, compliance's or scaled zero's is of, -1
    is_gain: np.ndarray  # (m,) a gain's column
    is_compliance: np.ndarray  # (m,) a compliance's column (else, with an actuator, a zero's)
    payload_kg: np.ndarray  # (m,) a compliance column's payload (NaN: per kg)
    gains: GainMap | None  # the model's gains
    compliance: ComplianceMap | None  # the model's compliances
    actuator_qpos: np.ndarray  # (A,)
    is_offset: np.ndarray | None = None  # (m,) an offset kind's column (calib.fit.kinds)
    offset_columns: OffsetMap | None = None  # the offset parameters of those columns

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
        extra_geo = extra.is_geometric if extra is not None else np.zeros(0, dtype=bool)
        geo = cols[params.is_geometric[cols]]
        rot = params.kind == BODY_ROT
        turned = np.unique(params.body[geo[rot[geo]]])
        index = np.union1d(geo, np.flatnonzero(rot & np.isin(params.body, turned)))
        gains = GainMap.of(params, mech)
        with_joints = not params.is_geometry or not bool(np.all(extra_geo))
        joints = list(actuator_joint_parameters(mech).parameters) if with_joints else []
        # the added ones renamed apart (a name of theirs may also be one of the model's)
        added = [Parameter(f"gain:{p.name}", p.kind, p.element, p.axis) for p in joints] + [
            Parameter(f"extra:{p.name}", p.kind, p.element, p.axis)
            for p, g in zip(extra_list, extra_geo, strict=True)
            if g
        ]
        chosen = ParameterSet([params.parameters[k] for k in index] + added, mech.model)
        n_idx, n_act = len(index), len(joints)
        # each returned column: its source, and the actuator whose gain or compliance enters it
        sets = [(params, cols)]
        if extra is not None:
            sets.append((extra, np.arange(len(extra))))
        source, actuator, is_gain, is_comp, payload = [], [], [], [], []
        is_off: list[bool] = []
        off_params, off_actuator, off_turns = [], [], []
        k_geo = n_idx + n_act
        for ps, chosen_cols in sets:
            acting = acting_actuators(ps, mech)
            zeroed = zeroed_actuators(ps, mech) if gains is not None else np.full(len(ps), -1)
            for c in chosen_cols:
                if not ps.is_geometric[c]:
                    source.append(n_idx + acting[c])
                    actuator.append(acting[c])
                elif ps is params:
                    source.append(int(np.searchsorted(index, c)))
                    actuator.append(zeroed[c])
                else:
                    source.append(k_geo)
                    k_geo += 1
                    actuator.append(zeroed[c])
                is_gain.append(bool(ps.is_gain[c]))
                is_comp.append(bool(ps.is_compliance[c]))
                payload.append(float(ps.payload_kg[c]))
                is_off.append(bool(ps.is_offset[c]))
                if is_off[-1]:
                    off_params.append(ps.parameters[c])
                    off_actuator.append(acting[c])
                    off_turns.append(bool(ps.turns[c]))
        offsets = None
        if off_params:
            offsets = OffsetMap(
                tuple(off_params),
                np.array(off_actuator, dtype=int),
                np.array(off_turns, dtype=bool),
                np.arange(len(off_params)),
                mech.n_actuators,
            )
        return cls(
            chosen,
            index,
            np.array(source, dtype=int),
            np.array(actuator, dtype=int),
            np.array(is_gain, dtype=bool),
            np.array(is_comp, dtype=bool),
            np.array(payload, dtype=float),
            gains,
            ComplianceMap.of(params, mech),
            np.asarray(mech.actuator_qpos, dtype=int),
            np.array(is_off, dtype=bool),
            offsets,
        )

    @property
    def needs_loads(self) -> bool:
        """Whether :meth:`assemble` needs the gravity loads (compliance columns, or gains'
        travels read through the model's compliances)."""
        return bool(np.any(self.is_compliance)) or (
            self.compliance is not None and bool(np.any(self.is_gain))
        )

    def offset_inputs(
        self, model: object, values: np.ndarray, commands: np.ndarray | None
    ) -> tuple[np.ndarray | None, np.ndarray | None] | None:
        """What :meth:`assemble` needs of the offset kinds at the ``commands`` (their rows'
        state bound to ``model``, a CalibrationModel): the basis of the offset columns and the
        model's joint offsets; None when no column is an offset's and the model has none."""
        own = getattr(model, "offsets", None)
        if self.offset_columns is None and own is None:
            return None
        if commands is None:
            raise ValueError(
                "the offset kinds' columns need the commands of the poses (a Prediction of "
                "CalibrationModel.predict carries them)"
            )
        basis = None
        if self.offset_columns is not None:
            basis = self.offset_columns.basis(commands, getattr(model, "state", None))
        return basis, model.offsets_at(values, commands)  # type: ignore[attr-defined]

    def values_for(self, values: np.ndarray) -> np.ndarray:
        """The values of ``params`` at the model's ``values``: the added ones at zero."""
        values = np.asarray(values, dtype=float)
        return np.concatenate([values[self.index], np.zeros(len(self.params) - len(self.index))])

    def assemble(
        self,
        jac: np.ndarray,
        values: np.ndarray,
        qpos: np.ndarray,
        zero: np.ndarray,
        loads: GravityLoads | None = None,
        shifts: tuple[np.ndarray | None, np.ndarray | None] | None = None,
    ) -> np.ndarray:
        """The returned columns (N, rows, m) from the twin's Jacobian ``jac`` (N, rows, n) of
        ``params`` at the closed configurations ``qpos`` (N, nq) of the model at ``values``,
        whose actuated joints' zeros are ``zero`` (A,); ``loads``: the gravity loads at
        ``qpos`` (when :attr:`needs_loads`); ``shifts``: :meth:`offset_inputs`' (the offset
        columns' basis, the model's joint offsets)."""
        out = jac[:, :, self.source]
        act = self.actuator >= 0
        if not np.any(act):
            return out
        g = self.gains.gains(values) if self.gains is not None else np.zeros(len(zero))
        gain_cols = np.flatnonzero(self.is_gain)
        if gain_cols.size:
            joints = qpos[:, self.actuator_qpos]
            if self.compliance is not None:  # the joint value before it yields
                assert loads is not None, "a gain's travel under compliances needs the loads"
                joints = joints + self.compliance.deflection(values, loads)
            if shifts is not None and shifts[1] is not None:  # the gained value alone
                joints = joints - shifts[1]
            travel = (joints - zero) / (1.0 + g)  # c - q0, (N, A)
            out[:, :, gain_cols] *= travel[:, None, self.actuator[gain_cols]]
        comp_cols = np.flatnonzero(self.is_compliance)
        if comp_cols.size:
            assert loads is not None, "compliance columns need the loads"
            load = load_columns(loads, self.actuator[comp_cols], self.payload_kg[comp_cols])
            out[:, :, comp_cols] *= -load[:, None, :]
        off = np.zeros(len(self.source), bool) if self.is_offset is None else self.is_offset
        off_cols = np.flatnonzero(off)
        if off_cols.size:
            assert shifts is not None and shifts[0] is not None, "offset columns need a basis"
            out[:, :, off_cols] *= shifts[0][:, None, :]
        zero_cols = np.flatnonzero(act & ~self.is_gain & ~self.is_compliance & ~off)
        if zero_cols.size:
            out[:, :, zero_cols] *= 1.0 + g[self.actuator[zero_cols]]
        return out
