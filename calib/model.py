"""The calibration model: the nominal mechanism plus named parameters, nothing of the truth.

It predicts tracker-target positions for actuator commands under given parameter values
(closed-chain forward kinematics of the injected model) and their identification Jacobian
(implicit-function form over the closed chain, all poses at once: twin.sensitivity_batch).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.kinematics_batch import forward_batch
from twin.mechanism import Mechanism
from twin.parameters import KINDS, Parameter, ParameterSet
from twin.sensitivity_batch import JacobianPlan, target_jacobian_batch
from twin.workspace import solve_poses


@dataclass(frozen=True)
class Prediction:
    targets: np.ndarray  # (P, T, 3) metres
    qpos: np.ndarray  # (P, nq) closed configurations, for the Jacobian


class CalibrationModel:
    """Nominal mechanism + error model; every evaluation injects values into a fresh copy."""

    def __init__(self, nominal: Mechanism, params: ParameterSet) -> None:
        self.nominal = nominal
        self.params = params
        self._cache_key: bytes | None = None
        self._cache_mech: Mechanism | None = None
        self._warm: tuple[bytes, np.ndarray] | None = None
        self._solved: tuple[tuple, np.ndarray] | None = None  # see commands_for_poses
        self._plan = JacobianPlan.for_mechanism(nominal)

    @property
    def n_parameters(self) -> int:
        return len(self.params)

    def mechanism(self, values: np.ndarray) -> Mechanism:
        """The nominal mechanism with ``values`` (SI) injected (cached for the last values)."""
        values = np.asarray(values, dtype=float)
        key = values.tobytes()
        if key != self._cache_key:
            model = self.params.inject(self.nominal.model, values)
            self._cache_mech = self.nominal.with_model(model)
            self._cache_key = key
        assert self._cache_mech is not None
        return self._cache_mech

    def commands_for_poses(self, values: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """:func:`twin.workspace.commands_for_poses` on the model with ``values`` (SI). The
        configurations it solved are kept (the last call's) for
        :meth:`solved_configurations`: a compensation of the same poses on the same model
        starts from them."""
        values = np.asarray(values, dtype=float)
        poses = np.atleast_2d(np.asarray(poses, dtype=float))
        commands, qpos = solve_poses(self.mechanism(values), poses)
        self._solved = ((values.tobytes(), poses.shape, poses.tobytes()), qpos)
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
        sol = forward_batch(self.mechanism(values), commands, start=start)
        self._warm = (key, sol.qpos)
        return Prediction(targets=sol.targets, qpos=sol.qpos)

    def jacobian(self, values: np.ndarray, prediction: Prediction) -> np.ndarray:
        """d(targets)/d(values), (P*T*3, n), rows ordered as ``targets.reshape(-1)``."""
        mech = self.mechanism(values)
        return target_jacobian_batch(mech, self.params, values, prediction.qpos, self._plan)


@dataclass(frozen=True)
class ColumnJacobian:
    """``model.jacobian(values, prediction)[:, columns]`` beside d(targets)/d(``extra``
    parameters at zero), in one batched pass over the poses and without the columns not
    asked for (a refit of some parameters evaluates it at every step).

    A body's rotation parameters compose into one rotation vector, which enters the screw
    of each: the other rotations of a body with a chosen one are computed along (and not
    returned), so each column is the one of the whole set."""

    model: CalibrationModel
    params: ParameterSet  # the chosen parameters, their companions, then the extra ones
    index: np.ndarray  # the model's parameter behind each of ``params`` but the extra ones
    pick: np.ndarray  # the columns returned: the chosen ones in order, then the extra ones

    @classmethod
    def of(
        cls, model: CalibrationModel, columns: np.ndarray, extra: ParameterSet | None = None
    ) -> ColumnJacobian:
        params, cols = model.params, np.asarray(columns, dtype=int)
        rot = params.kind == KINDS.index("body_rot")
        turned = np.unique(params.body[cols[rot[cols]]])
        index = np.union1d(cols, np.flatnonzero(rot & np.isin(params.body, turned)))
        # the extra ones renamed apart (a name of theirs may also be one of the model's)
        added = [
            Parameter(f"extra:{p.name}", p.kind, p.element, p.axis)
            for p in (extra.parameters if extra is not None else ())
        ]
        chosen = ParameterSet([params.parameters[k] for k in index] + added, model.nominal.model)
        pick = np.concatenate([np.searchsorted(index, cols), len(index) + np.arange(len(added))])
        return cls(model, chosen, index, pick)

    def __call__(self, values: np.ndarray, prediction: Prediction) -> np.ndarray:
        """(P*T*3, len(columns) + len(extra)) at ``values`` (every parameter of the model)."""
        values = np.asarray(values, dtype=float)
        v = np.concatenate([values[self.index], np.zeros(len(self.params) - len(self.index))])
        mech = self.model.mechanism(values)
        jac = target_jacobian_batch(mech, self.params, v, prediction.qpos, self.model._plan)
        return jac[:, self.pick]
