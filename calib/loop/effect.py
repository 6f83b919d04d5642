"""An effect as a correction of the actuator commands: joint values = commands + D theta.

Closing the loop after a residual diagnosis needs the named effect as part of the machine
model: the joint values the machine really takes for commands c are ``c + D(c, t) theta``
with the effect's regressor D (N, A, k) and fitted coefficients theta (k,). The regressor is
the candidate's own (calib.diagnosis.core: gain, lead of a given pitch, backlash by approach
direction, thermal growth or drift with a given time constant, gravity compliance with a
given payload), taken through the public :func:`calib.diagnosis.core.effect_offsets`; its shape
(pitch, time constant, payload) stays at the value the diagnosis chose. Effects that are not
actuator offsets (tracker drift, geometric columns) have no correction here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calib.diagnosis.core import default_candidates, effect_offsets
from calib.fit.model import CalibrationModel

# a regressor: (commands (N, A), order (N,)) -> D (N, A, k)
Regressor = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class ActuatorCorrection:
    """``offsets(c, t) = D(c, t) theta``: the correction of the commands, per actuator."""

    names: tuple[str, ...]  # one per coefficient (effect.parameter)
    regressor: Regressor
    theta: np.ndarray  # (k,) SI

    @property
    def n_coefficients(self) -> int:
        return len(self.theta)

    def offsets(
        self, commands: np.ndarray, order: np.ndarray, theta: np.ndarray | None = None
    ) -> np.ndarray:
        """Actuator offsets (N, A) for commands measured in sequence ``order``."""
        t = self.theta if theta is None else np.asarray(theta, dtype=float)
        if t.size == 0:
            return np.zeros_like(np.asarray(commands, dtype=float))
        return np.einsum("nak,k->na", self.regressor(commands, order), t)

    def joints(
        self, commands: np.ndarray, order: np.ndarray, theta: np.ndarray | None = None
    ) -> np.ndarray:
        """Joint values (N, A) the corrected model takes for ``commands``."""
        return np.asarray(commands, dtype=float) + self.offsets(commands, order, theta)

    def with_theta(self, theta: np.ndarray) -> ActuatorCorrection:
        return ActuatorCorrection(self.names, self.regressor, np.asarray(theta, dtype=float))


def diagnosed_correction(
    model: CalibrationModel,
    values: np.ndarray,
    chosen: dict[str, np.ndarray],
    time_origin: float = 0.0,
    time_unit: str = "pose",
) -> ActuatorCorrection:
    """The actuator-level effects a diagnosis named (``Diagnosis.coefficients``) as one
    correction: linear coefficients free, shapes (the last entry of a shaped candidate's
    coefficients) fixed. Effects that are not actuator offsets are left out."""
    mech = model.nominal
    # the library effect_offsets builds by default, built once here for every evaluation
    candidates = default_candidates(
        mech.actuator_names, mech.actuator_is_slide, mech.masses_defaulted
    )
    lib = {c.name: c for c in candidates}
    parts: list[tuple[str, int, float | None]] = []  # name, k, shape
    names: list[str] = []
    theta: list[float] = []
    for name, coef in chosen.items():
        c = lib.get(name)
        if c is None or c.offsets is None:
            continue
        coef = np.asarray(coef, dtype=float)
        lin, shape = (coef[:-1], float(coef[-1])) if c.shaped else (coef, None)
        parts.append((name, len(lin), shape))
        names += [f"{name}.{p}" for p in c.parameters[: len(lin)]]
        theta += list(lin)
    geometry = np.array(values, dtype=float)

    def regressor(commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        cols = []
        for name, k, shape in parts:
            for j in range(k):
                unit = np.zeros(k + (shape is not None))
                unit[j] = 1.0
                if shape is not None:
                    unit[-1] = shape
                cols.append(
                    effect_offsets(
                        model,
                        geometry,
                        commands,
                        order,
                        {name: unit},
                        candidates,
                        time_origin=time_origin,
                        time_unit=time_unit,
                    )
                )
        n, a = np.shape(commands)
        return np.stack(cols, axis=2) if cols else np.zeros((n, a, 0))

    return ActuatorCorrection(tuple(names), regressor, np.array(theta, dtype=float))
