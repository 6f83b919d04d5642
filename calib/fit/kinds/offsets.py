"""The offset kinds in the calibration model: joint values, inverse, identification columns.

An offset parameter ``v`` of actuator ``a`` (twin.offset_kinds) adds ``v phi(c, state)`` to
the joint value the command asks (after the actuator's gain, before a compliance yields it):

    q_a = G_a(c_a) + sum_k v_k phi_k(c_a, state),

``phi`` depending on the command and on the state at the reading (calib.fit.kinds.state), not
on the parameter values, so the joint value is linear in ``v`` and the identification column of
``v`` is the actuator joint's column times ``phi_k`` per pose. The geometry's columns are
unchanged; a gain's travel is read from the joint value less the offsets.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calib.fit.kinds.state import PoseState
from twin.mechanism import Mechanism
from twin.offset_kinds import needed_column
from twin.parameters import Parameter, ParameterSet


def growth(t: np.ndarray, tau: float | None) -> np.ndarray:
    """h(t) = tau (1 - exp(-t / tau)); h(t) = t without a time constant (unit initial rate)."""
    t = np.asarray(t, dtype=float)
    return t if tau is None else tau * -np.expm1(-t / tau)


@dataclass(frozen=True)
class OffsetMap:
    """Offset parameters (in some order), their actuators and what each needs."""

    parameters: tuple[Parameter, ...]
    actuator: np.ndarray  # (K,) the actuator (command column) each offsets
    turns: np.ndarray  # (K,) its joint turns
    index: np.ndarray  # (K,) where each parameter's value is in the values it is given
    n_actuators: int

    @classmethod
    def of(cls, params: ParameterSet, mech: Mechanism) -> OffsetMap | None:
        """The offset parameters of ``params``; None if it has none."""
        k = np.flatnonzero(params.is_offset)
        return cls.of_columns(params, mech, k, k) if k.size else None

    @classmethod
    def of_columns(
        cls, params: ParameterSet, mech: Mechanism, columns: Sequence[int], index: Sequence[int]
    ) -> OffsetMap:
        """The offset parameters ``columns`` of ``params``, their values at ``index``."""
        cols = np.asarray(columns, dtype=int)
        names = list(mech.actuator_names)
        return cls(
            tuple(params.parameters[c] for c in cols),
            np.array([names.index(params.parameters[c].element) for c in cols], dtype=int),
            np.asarray(params.turns, dtype=bool)[cols],
            np.asarray(index, dtype=int),
            mech.n_actuators,
        )

    def __len__(self) -> int:
        return len(self.parameters)

    @property
    def needs(self) -> tuple[str, ...]:
        """The state columns the parameters read (empty: a function of the commands alone)."""
        out = [needed_column(p.kind, p.constants_dict) for p in self.parameters]
        return tuple(sorted({c for c in out if c is not None}))

    def basis(self, commands: np.ndarray, state: PoseState | None) -> np.ndarray:
        """phi (N, K) of each parameter at the commands (N, A) in the state of their rows."""
        c = np.atleast_2d(np.asarray(commands, dtype=float))
        n = len(c)
        if self.needs and (state is None or state.n != n):
            got = "no state" if state is None else f"the state of {state.n} readings"
            raise ValueError(
                f"the offsets {[p.name for p in self.parameters][:3]} read the state of each "
                f"reading ({', '.join(self.needs)}), but {n} commands came with {got}"
            )
        out = np.zeros((n, len(self)))
        for k, p in enumerate(self.parameters):
            out[:, k] = _phi(p, bool(self.turns[k]), c[:, self.actuator[k]], state, k, self)
        return out

    def offsets(
        self, values: np.ndarray, commands: np.ndarray, state: PoseState | None
    ) -> np.ndarray:
        """The joint offsets (N, A) at the commands: sum of v phi per actuator."""
        v = np.asarray(values, dtype=float)[self.index]
        contrib = self.basis(commands, state) * v[None, :]
        out = np.zeros((len(contrib), self.n_actuators))
        for a in range(self.n_actuators):
            out[:, a] = contrib[:, self.actuator == a].sum(axis=1)
        return out


def _phi(
    p: Parameter, turns: bool, c: np.ndarray, state: PoseState | None, k: int, owner: OffsetMap
) -> np.ndarray:
    consts = p.constants_dict
    who = f"parameter '{p.name}' ({p.kind})"
    if p.kind == "periodic_error":
        arg = (
            float(consts["harmonic"]) * c
            if turns
            else 2 * np.pi * c / (1e-3 * float(consts["period_mm"]))
        )
        return np.sin(arg) if consts["phase"] == "sin" else np.cos(arg)
    assert state is not None
    if p.kind == "backlash":
        return -state.column("direction", who)[:, owner.actuator[k]]
    if p.kind == "thermal_expansion":
        return (state.column("temperature_c", who) - float(consts.get("origin", 20.0))) * c
    t = state.column(str(consts["clock"]), who) - float(consts.get("origin", 0.0))
    tau = consts.get("time_constant")
    h = growth(t, None if tau is None else float(tau))
    return h * c if p.kind == "thermal_growth" else h
