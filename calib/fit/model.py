"""The calibration model: the nominal mechanism plus named parameters, nothing of the truth.

It predicts tracker-target positions for actuator commands under given parameter values
(closed-chain forward kinematics of the injected model) and their identification Jacobian
(implicit-function form over the closed chain, all poses at once:
twin.kinematics.sensitivity_batch).
Actuator gains among the parameters map the commands to joint values first, joint
compliances then let each joint yield to its gravity load (calib.fit.joint_compliance: the
joints settle at a fixed point), and their columns are assembled beside the geometric ones
(calib.fit.actuator_gains); everything that asks the model (identify, verify, the compensation)
sees commands in and commands out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.diagnosis.gravity import GravityLoads, gravity_loads
from calib.fit.actuator_gains import ColumnPlan, GainMap
from calib.fit.joint_compliance import ComplianceMap, Settled, settle
from calib.fit.kinds import OffsetMap, PoseState
from twin.exceptions import ClosureError, ModelError
from twin.kinematics.batch import forward_batch
from twin.kinematics.sensitivity_batch import (
    JacobianPlan,
    target_jacobian_batch,
    tool_twist_jacobian_batch,
)
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet
from twin.workspace import check_command_strokes, solve_poses


@dataclass(frozen=True)
class Prediction:
    targets: np.ndarray  # (P, T, 3) metres
    qpos: np.ndarray  # (P, nq) closed configurations, for the Jacobian
    commands: np.ndarray | None = None  # (P, A) the commands, for the offsets' columns


class CalibrationModel:
    """Nominal mechanism + error model; every evaluation injects values into a fresh copy."""

    def __init__(self, nominal: Mechanism, params: ParameterSet) -> None:
        if nominal.is_geared:
            geared = [
                f"{n} (gear {g!r})"
                for n, g in zip(nominal.actuator_names, nominal.actuator_gear, strict=True)
                if g != 1.0
            ]
            raise ModelError(
                f"model '{nominal.name}' has actuators whose joint is not their command: "
                f"{', '.join(geared[:3])}: a calibrated model with its gains (calib export). "
                "Calibrate the nominal model (with the result's gains: identify --with), or "
                "score this one as it is (verify --model without --result)"
            )
        self.nominal = nominal
        self.params = params
        self._cache_key: bytes | None = None
        self._cache_mech: Mechanism | None = None
        self._warm: tuple[bytes, np.ndarray] | None = None
        self._solved: tuple[tuple, np.ndarray] | None = None  # see commands_for_poses
        self._plan = JacobianPlan.for_mechanism(nominal)
        self.gains = GainMap.of(params, nominal)  # None without actuator_gain parameters
        self.compliance = ComplianceMap.of(params, nominal)  # None without joint compliances
        self._every_column: ColumnPlan | None = None  # with gains or compliances: _columns
        self._loads: tuple[bytes, GravityLoads] | None = None  # at the last settled poses
        self.offsets = OffsetMap.of(params, nominal)  # None without offset kinds
        self.state: PoseState | None = None  # of the readings the commands are of

    def bind_state(self, state: PoseState | None) -> None:
        """The state (approach directions, time, temperature) of the readings whose commands
        the model is given next: the offset kinds read it row by row (calib.fit.kinds)."""
        self.state = state

    def offsets_at(self, values: np.ndarray, commands: np.ndarray) -> np.ndarray | None:
        """The joint offsets (N, A) of the offset kinds at the commands (None without)."""
        if self.offsets is None:
            return None
        return self.offsets.offsets(values, commands, self.state)

    def offset_basis(self, commands: np.ndarray) -> np.ndarray | None:
        """phi (N, K) of the offset parameters at the commands in the bound state."""
        return None if self.offsets is None else self.offsets.basis(commands, self.state)

    @property
    def n_parameters(self) -> int:
        return len(self.params)

    def mechanism(self, values: np.ndarray) -> Mechanism:
        """The nominal mechanism with ``values`` (SI) injected (cached for the last values;
        gains and compliances are no geometry, so values differing only in them share it)."""
        values = np.asarray(values, dtype=float)
        key = self._geometry_key(values)
        if key != self._cache_key:
            model = self.params.inject(self.nominal.model, values)
            self._cache_mech = self.nominal.with_model(model)
            self._cache_key = key
        assert self._cache_mech is not None
        return self._cache_mech

    def _geometry_key(self, values: np.ndarray) -> bytes:
        if self.params.is_geometry:
            return values.tobytes()
        return values[self.params.is_geometric].tobytes()

    def joint_zeros(self, values: np.ndarray) -> np.ndarray:
        """The actuated joints' zeros (A,) of the model at ``values`` (its ``qpos0``)."""
        return self.mechanism(values).model.qpos0[self.nominal.actuator_qpos]

    def joints_for_commands(self, values: np.ndarray, commands: np.ndarray) -> np.ndarray:
        """The actuated joints' values (N, A) the commands (N, A) give (the commands
        themselves without gains or compliances; under compliances where the joints settle,
        rows that are not finite left NaN)."""
        joints = self._gained(values, commands)
        if self.compliance is None:
            return joints
        out = np.full(joints.shape, np.nan)
        ok = np.all(np.isfinite(joints), axis=1)
        if np.any(ok):
            out[ok] = self._settle(values, joints[ok]).joints
        return out

    def _gained(self, values: np.ndarray, commands: np.ndarray) -> np.ndarray:
        """The joint values (N, A) the commands ask through the gains (before compliances)."""
        if self.gains is None:
            joints = np.asarray(commands, dtype=float)
        else:
            joints = self.gains.joints(values, commands, self.joint_zeros(values))
        shift = self.offsets_at(values, commands)
        return joints if shift is None else joints + shift

    def _settle(
        self, values: np.ndarray, joints: np.ndarray, start: np.ndarray | None = None
    ) -> Settled:
        """calib.fit.joint_compliance.settle on the model at ``values``; its loads are kept for
        the Jacobian at the same configurations."""
        assert self.compliance is not None
        mech = self.mechanism(values)
        done = settle(mech, self.compliance, values, joints, start)
        key = self._geometry_key(np.asarray(values, dtype=float)) + done.solution.qpos.tobytes()
        self._loads = (key, done.loads)
        return done

    def loads(self, values: np.ndarray, qpos: np.ndarray) -> GravityLoads:
        """The actuators' gravity loads at the closed configurations ``qpos`` (N, nq) of the
        model at ``values`` (calib.diagnosis.gravity; those of the last settled poses when
        they are these)."""
        qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
        key = self._geometry_key(np.asarray(values, dtype=float)) + qpos.tobytes()
        if self._loads is None or self._loads[0] != key:
            mech = self.mechanism(values)
            self._loads = (key, gravity_loads(mech, qpos, self.nominal.masses_defaulted))
        return self._loads[1]

    def commands_for_joints(
        self, values: np.ndarray, joints: np.ndarray, qpos: np.ndarray | None = None
    ) -> np.ndarray:
        """The commands (N, A) that give the actuated joints' values (N, A): the joint value
        plus its deflection under the loads there (``qpos`` (N, nq): the closed
        configurations of the joints, if known; else solved), then through the gains. Rows
        that are not finite stay NaN."""
        q = np.asarray(joints, dtype=float)
        if self.compliance is not None:
            q = q.copy()
            ok = np.all(np.isfinite(q), axis=1)
            if np.any(ok):
                mech = self.mechanism(values)
                if qpos is None:
                    at = forward_batch(mech, q[ok], check_stroke=False).qpos
                else:
                    at = np.atleast_2d(np.asarray(qpos, dtype=float))[ok]
                q[ok] += self.compliance.deflection(values, self.loads(values, at))
        return self._ungained(values, q)

    def _ungained(self, values: np.ndarray, joints: np.ndarray) -> np.ndarray:
        """The commands whose gained joint values plus offsets are ``joints`` (N, A): the
        offsets of the commands found (a periodic one's shifts its own phase by v/period, a
        few parts in a thousand: rounds of the fixed point until no command changes)."""
        q = np.asarray(joints, dtype=float)

        def ungain(j: np.ndarray) -> np.ndarray:
            return (
                j
                if self.gains is None
                else self.gains.commands(values, j, self.joint_zeros(values))
            )

        c = ungain(q)
        if self.offsets is None:
            return c
        for _ in range(100):
            new = ungain(q - self.offsets_at(values, c))
            done = bool(np.all(np.abs(new - c)[np.isfinite(new)] <= 1e-15))
            c = new
            if done:
                break
        return c

    def commands_for_poses(self, values: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """:func:`twin.workspace.commands_for_poses` on the model with ``values`` (SI), the
        joint values it solves turned into commands through the compliances and the gains
        (the strokes are checked on both). The configurations it solved are kept (the last
        call's) for :meth:`solved_configurations`: a compensation of the same poses on the
        same model starts from them."""
        values = np.asarray(values, dtype=float)
        poses = np.atleast_2d(np.asarray(poses, dtype=float))
        mech = self.mechanism(values)
        joints, qpos = solve_poses(mech, poses)
        self._solved = ((values.tobytes(), poses.shape, poses.tobytes()), qpos)
        if self.params.is_geometry:
            return joints
        commands = self.commands_for_joints(values, joints, qpos)
        check_command_strokes(mech, commands)  # what predict accepts
        return commands

    def solved_configurations(self, values: np.ndarray, poses: np.ndarray) -> np.ndarray | None:
        """The closed configurations (N, nq) of ``poses`` that :meth:`commands_for_poses`
        solved last, if it solved these poses for these ``values`` (a copy); else None."""
        values = np.asarray(values, dtype=float)
        poses = np.atleast_2d(np.asarray(poses, dtype=float))
        key = (values.tobytes(), poses.shape, poses.tobytes())
        if self._solved is None or self._solved[0] != key:
            return None
        return self._solved[1].copy()

    def predict(self, values: np.ndarray, commands: np.ndarray) -> Prediction:
        """Targets at ``commands`` for parameter ``values``. Solving the same commands again
        (as an estimator does for nearby values) starts from the previous solution."""
        commands = np.asarray(commands, dtype=float)
        key = commands.tobytes()
        start = self._warm[1] if self._warm is not None and self._warm[0] == key else None
        mech = self.mechanism(values)
        if self.params.is_geometry:
            sol = self._closed(mech, commands, start, True)
        else:
            q = self._checked_joints(mech, values, commands)
            if self.compliance is None:
                sol = self._closed(mech, q, start, False)
            else:
                sol = self._settle(values, q, start).solution
        self._warm = (key, sol.qpos)
        return Prediction(targets=sol.targets, qpos=sol.qpos, commands=commands)

    def _closed(self, mech: Mechanism, q: np.ndarray, start, check_stroke: bool):
        """forward_batch; where its start leaves a pose unclosed (a stall on the far side of
        it), again from the predictor's start and from the nominal machine's own solution of
        the same commands (a polisher pose stalled at 2e-11 m from a warm start)."""
        try:
            return forward_batch(mech, q, start=start, check_stroke=check_stroke)
        except ClosureError:
            if start is None:
                start = forward_batch(self.nominal, q, check_stroke=False).qpos
            else:  # a warm start from other values: the predictor's own start
                try:
                    return forward_batch(mech, q, check_stroke=check_stroke)
                except ClosureError:
                    start = forward_batch(self.nominal, q, check_stroke=False).qpos
        return forward_batch(mech, q, start=start, check_stroke=check_stroke)

    def _checked_joints(
        self, mech: Mechanism, values: np.ndarray, commands: np.ndarray
    ) -> np.ndarray:
        """The joints of ``commands`` with the errors forward kinematics gives commands (shape,
        finite, strokes) checked on the commands: the joints a gain moves may leave a stroke
        by its ppm, as the machine's own would."""
        c = np.atleast_2d(commands)
        lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
        if c.shape[1:] != (mech.n_actuators,) or not np.all(np.isfinite(c)):
            forward_batch(mech, c)  # raises the error it gives such commands
        if np.any((c < lo - 1e-12) | (c > hi + 1e-12)):
            check_command_strokes(mech, c)
        return self._gained(values, c)

    def jacobian(self, values: np.ndarray, prediction: Prediction) -> np.ndarray:
        """d(targets)/d(values), (P*T*3, n), rows ordered as ``targets.reshape(-1)``."""
        mech = self.mechanism(values)
        if self.params.is_geometry:
            return target_jacobian_batch(mech, self.params, values, prediction.qpos, self._plan)
        return ColumnJacobian(self, self._columns())(values, prediction)

    def tool_twist_jacobian(
        self, values: np.ndarray, qpos: np.ndarray, commands: np.ndarray | None = None
    ) -> np.ndarray:
        """d(tool pose error twist)/d(values) (N, 6, n) at the closed configurations ``qpos``
        (N, nq) of the model at ``values``
        (twin.kinematics.sensitivity_batch.tool_twist_jacobian_batch
        with the gains' and the compliances' columns; the offsets' need the ``commands``)."""
        mech = self.mechanism(values)
        if self.params.is_geometry:
            return tool_twist_jacobian_batch(mech, self.params, values, qpos, self._plan)
        plan = self._columns()
        jac = tool_twist_jacobian_batch(
            mech, plan.params, plan.values_for(values), qpos, self._plan
        )
        qpos = np.atleast_2d(qpos)
        loads = self.loads(values, qpos) if plan.needs_loads else None
        shifts = plan.offset_inputs(self, values, commands)
        return plan.assemble(jac, values, qpos, self.joint_zeros(values), loads, shifts)

    def _columns(self) -> ColumnPlan:
        """The plan of every column (built once)."""
        if self._every_column is None:
            self._every_column = ColumnPlan.of(
                self.params, self.nominal, np.arange(len(self.params))
            )
        return self._every_column


@dataclass(frozen=True)
class ColumnJacobian:
    """``model.jacobian(values, prediction)[:, columns]`` beside d(targets)/d(``extra``
    parameters at zero), in one batched pass over the poses and without the columns not
    asked for (a refit of some parameters evaluates it at every step).

    A body's rotation parameters compose into one rotation vector, which enters the screw
    of each: the other rotations of a body with a chosen one are computed along (and not
    returned), so each column is the one of the whole set. Actuator gains (the model's or
    among ``extra``) and joint zeros of gained actuators get their columns as
    calib.fit.actuator_gains says: an extra joint zero of an actuated joint is then the
    derivative with respect to that actuator's command. Compliances (the model's or among
    ``extra``) get theirs with the loads at the prediction's configurations."""

    model: CalibrationModel
    plan: ColumnPlan

    @property
    def params(self) -> ParameterSet:
        """What the twin differentiates: the chosen parameters, their companions, the
        actuators' joints (with gains), then the extra geometry."""
        return self.plan.params

    @classmethod
    def of(
        cls, model: CalibrationModel, columns: np.ndarray, extra: ParameterSet | None = None
    ) -> ColumnJacobian:
        return cls(model, ColumnPlan.of(model.params, model.nominal, columns, extra))

    def __call__(self, values: np.ndarray, prediction: Prediction) -> np.ndarray:
        """(P*T*3, len(columns) + len(extra)) at ``values`` (every parameter of the model)."""
        values = np.asarray(values, dtype=float)
        plan = self.plan
        mech = self.model.mechanism(values)
        qpos = prediction.qpos
        jac = target_jacobian_batch(
            mech, plan.params, plan.values_for(values), qpos, self.model._plan
        )
        if not np.any(plan.actuator >= 0):
            return jac[:, plan.source]
        rows = jac.reshape(len(qpos), -1, len(plan.params))
        loads = self.model.loads(values, qpos) if plan.needs_loads else None
        shifts = plan.offset_inputs(self.model, values, prediction.commands)
        out = plan.assemble(rows, values, qpos, self.model.joint_zeros(values), loads, shifts)
        return out.reshape(-1, len(plan.source))
