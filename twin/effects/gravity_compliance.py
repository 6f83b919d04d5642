"""Gravity-induced deflection: compliant actuators under the machine's own weight.

MuJoCo supplies the physics: with gravity on and the machine at rest at its closed
configuration, ``qfrc_bias`` is the generalized gravity load of the real mass distribution
(plus an optional payload on the tool body). The static equilibrium

    qfrc_bias = J_c^T lambda + S^T tau

(closure constraint forces lambda, actuator forces tau on the actuated joints S) is solved by
least squares; each actuator, a spring of stiffness k (axial N/m for prismatic, N m/rad for
revolute drives), then yields to q = q_cmd - tau / k, and the closure is solved again at
the new joint values (fixed point, a few rounds, until they change by less than 1e-12).

On a model whose masses were defaulted (a kinematics-only MJCF, ``masses_defaulted``) the
1 g placeholders are not the machine's: they are removed and only the payload loads the
machine; without a payload there is nothing to deflect and the effect raises ModelError.
The payload sits at the tool body's centre of mass here (``joint_compliance`` puts it at the
tool point).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.exceptions import ModelError
from twin.kinematics.closure import closure_jacobian, update_kinematics
from twin.kinematics.single_pose import forward
from twin.mechanism import Mechanism


def gravity_model(
    mech: Mechanism, gravity: tuple[float, float, float], payload_kg: float, what: str
) -> mujoco.MjModel:
    """A copy of the model with gravity on; defaulted masses removed (payload only)."""
    model = copy.deepcopy(mech.model)
    model.opt.gravity[:] = gravity
    if mech.masses_defaulted:
        if payload_kg <= 0.0:
            raise ModelError(
                f"{what}: the masses of '{mech.name}' were defaulted (its MJCF declares none), "
                "so its own weight is unknown; give payload_kg > 0 to load it with a payload only"
            )
        model.body_mass[:] = 0.0
    return model


def actuator_forces(mech: Mechanism, qpos: np.ndarray) -> np.ndarray:
    """Forces (N or N m) the actuators exert to hold ``mech`` still at ``qpos`` under gravity:
    the static split of MuJoCo's ``qfrc_bias`` into closure and actuator forces."""
    m, d = mech.model, mech.data
    d.qpos[:] = qpos
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    bias = d.qfrc_bias.copy()
    update_kinematics(mech, qpos)
    jc = closure_jacobian(mech)
    sel = np.zeros((mech.n_actuators, m.nv))
    sel[np.arange(mech.n_actuators), mech.actuator_dofs] = 1.0
    a = np.vstack([jc, sel]).T  # (nv, n_closure + A)
    sol, *_ = np.linalg.lstsq(a, bias, rcond=None)
    return sol[jc.shape[0] :]


def static_deflection(
    heavy: Mechanism, commands: np.ndarray, stiffness: np.ndarray, max_rounds: int
) -> np.ndarray:
    """Joint values (N, A) of actuators (springs of ``stiffness``, inf = rigid) holding the
    loaded machine ``heavy`` at rest at ``commands``: q = q_cmd - tau(q) / k, fixed point."""
    out = np.array(commands, dtype=float)
    for i, c in enumerate(commands):
        q_act = c.copy()
        start = None
        for _ in range(max_rounds):
            sol = forward(heavy, q_act, start=start, check_stroke=False)
            tau = actuator_forces(heavy, sol.qpos)
            new = c - tau / stiffness
            start = sol.qpos
            if np.max(np.abs(new - q_act)) < 1e-12:
                q_act = new
                break
            q_act = new
        out[i] = q_act
    return out


@dataclass(frozen=True)
class GravityCompliance:
    stiffness_N_per_m: float = 2e7  # a ball-screw actuator of about 20 N/um
    stiffness_Nm_per_rad: float = 2e5  # a geared rotary drive
    payload_kg: float = 0.0  # added to the tool's body (e.g. a mirror or a spindle)
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    max_rounds: int = 10
    name: str = "gravity_compliance"

    def loaded(self, mech: Mechanism) -> Mechanism:
        """A copy of the machine with gravity on and the payload added."""
        model = gravity_model(mech, self.gravity, self.payload_kg, self.name)
        model.body_mass[mech.tool_body] += self.payload_kg
        return mech.with_model(model)

    def actuator_forces(self, mech: Mechanism, qpos: np.ndarray) -> np.ndarray:
        """Forces (N) the actuators exert to hold the machine still at ``qpos``."""
        return actuator_forces(mech, qpos)

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        heavy = self.loaded(mech)
        stiffness = np.where(
            mech.actuator_is_slide, self.stiffness_N_per_m, self.stiffness_Nm_per_rad
        )
        return static_deflection(heavy, commands, stiffness, self.max_rounds)
