"""Joint compliance in the calibration model: joints that yield to their gravity load.

A ``joint_compliance`` parameter ``k`` of actuator ``a`` (twin.parameters) makes its joint
take, for the joint value ``j`` its command asks (the command itself, or through the
actuator's gain: calib.fit.actuator_gains),

    q_a = j_a - sum_k k L_k(q),

``L_k`` the parameter's load at the configuration the machine settles in: the static force or
torque the actuator holds there under gravity, computed from the calibration's own model as
the diagnosis computes it (calib.diagnosis.gravity.gravity_loads, the model's geometry at the
current values). With ``payload_kg`` m it is the load of the model's own masses plus m
kilograms at the tool site (a model whose masses MuJoCo defaulted has no own weight: the
payload's alone) and ``k`` a compliance; without, the load of one kilogram at the tool site and
``k`` the compliance times the payload's mass (all a model without declared masses can know).

The loads depend on the pose the deflection changes, so the joints are the fixed point of the
map above: rounds of forward kinematics and loads until a round changes no joint by more than
``SETTLED`` (a stiff drive deflects by k L ~ 1e-3 rad and its load changes by k dL/dq ~ 1e-3
of that per round: four or five rounds). The inverse needs no rounds: the commands of joint
values q are ``j = q + sum_k k L_k(q)`` at the configuration of q.

Identification columns hold the loads at the settled configuration (the terms of dL/dq and
dL/d(geometry), relative size k dL/dq, are left out): a compliance's column is the actuator
joint's column times ``-L_k`` per pose; the geometry's are the geometric ones. At zero
compliance (where identify starts) they are the exact derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from calib.diagnosis.gravity import GravityLoads, gravity_loads
from calib.exceptions import ConvergenceError
from twin.kinematics.batch import BatchSolution, forward_batch
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet

SETTLED = 1e-14  # rad or m: a round that changes no joint by more than this has settled
MAX_ROUNDS = 60


def acting_actuators(params: ParameterSet, mech: Mechanism) -> np.ndarray:
    """The actuator (command column of ``mech``) each parameter's gain or compliance acts on,
    -1 for a geometric parameter (n,)."""
    out = np.full(len(params), -1, dtype=int)
    for k in np.flatnonzero(~params.is_geometric):
        name = mujoco.mj_id2name(mech.model, mujoco.mjtObj.mjOBJ_ACTUATOR, int(params.element[k]))
        out[k] = mech.actuator_names.index(name)
    return out


def load_columns(loads: GravityLoads, actuator: np.ndarray, payload_kg: np.ndarray) -> np.ndarray:
    """The load (N, K) of each compliance (its ``actuator`` and ``payload_kg``, NaN: per kg
    of payload) at the poses of ``loads``."""
    unit = loads.unit_payload[:, actuator]
    per_kg = np.isnan(payload_kg)
    if np.all(per_kg):
        return unit
    own = loads.own[:, actuator] + np.where(per_kg, 0.0, payload_kg) * unit
    return np.where(per_kg, unit, own)


@dataclass(frozen=True)
class ComplianceMap:
    """The compliance parameters of a model's parameter set, their actuators and loads."""

    index: np.ndarray  # (K,) the parameters that are compliances
    actuator: np.ndarray  # (K,) the actuator each yields
    payload_kg: np.ndarray  # (K,) its payload, NaN: per kg of payload
    n_actuators: int
    masses_defaulted: bool  # the model's own masses are MuJoCo's placeholders: no own load

    @classmethod
    def of(cls, params: ParameterSet, mech: Mechanism) -> ComplianceMap | None:
        """The compliances of ``params`` on ``mech``; None if it has none."""
        if not params.has_compliance:
            return None
        index = np.flatnonzero(params.is_compliance)
        return cls(
            index,
            acting_actuators(params, mech)[index],
            params.payload_kg[index],
            mech.n_actuators,
            mech.masses_defaulted,
        )

    def loads(self, mech: Mechanism, qpos: np.ndarray) -> GravityLoads:
        """The actuators' gravity loads at the closed configurations ``qpos`` (N, nq) of
        ``mech`` (the model at the current values)."""
        return gravity_loads(mech, np.atleast_2d(qpos), self.masses_defaulted)

    def deflection(self, values: np.ndarray, loads: GravityLoads) -> np.ndarray:
        """How far (N, A) each actuator's joint yields: sum of its compliances' k L_k."""
        k = np.asarray(values, dtype=float)[self.index]
        terms = load_columns(loads, self.actuator, self.payload_kg) * k
        out = np.zeros((terms.shape[0], self.n_actuators))
        np.add.at(out.T, self.actuator, terms.T)
        return out


@dataclass(frozen=True)
class Settled:
    joints: np.ndarray  # (N, A) the actuated joints' values the machine settles at
    solution: BatchSolution  # the forward kinematics there
    loads: GravityLoads  # the loads there
    rounds: int


def settle(
    mech: Mechanism,
    compliance: ComplianceMap,
    values: np.ndarray,
    joints: np.ndarray,
    start: np.ndarray | None = None,
) -> Settled:
    """The joints (N, A) the commanded joint values ``joints`` settle at under the
    compliances (``values`` every parameter's), by rounds of ``q = joints - D(q)`` from
    ``start`` (closed configurations (N, nq) of a nearby solution, e.g. the last values', or
    None: from the joints asked). Raises ConvergenceError if they do not settle."""
    joints = np.atleast_2d(np.asarray(joints, dtype=float))
    q = joints if start is None else np.asarray(start, dtype=float)[:, mech.actuator_qpos]
    change = np.inf
    for rounds in range(1, MAX_ROUNDS + 1):
        sol = forward_batch(mech, q, start=start, check_stroke=False)
        loads = compliance.loads(mech, sol.qpos)
        new = joints - compliance.deflection(values, loads)
        change = float(np.max(np.abs(new - q))) if q.size else 0.0
        if change <= SETTLED:
            return Settled(q, sol, loads, rounds)
        q, start = new, sol.qpos
    raise ConvergenceError(
        f"the joints under the joint compliances did not settle in {MAX_ROUNDS} rounds (last "
        f"change {change:.3g}): a compliance this large makes the load grow faster than the "
        "joint yields (k dtau/dq >= 1), which no standing machine does"
    )
