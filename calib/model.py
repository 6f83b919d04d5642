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
from twin.parameters import ParameterSet
from twin.sensitivity_batch import JacobianPlan, target_jacobian_batch


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
