"""Static actuator loads under gravity, from the calibration's own (nominal) model.

At a closed configuration q the generalised force gravity asks of the joints is MuJoCo's
``qfrc_bias`` with zero velocity (``mj_rne``). The actuators carry it through the closure:
with the actuated coordinates independent, the free ones follow as
dq_free = -C_free^+ C_act dq_act (C the closure Jacobian), so by virtual work the actuator
forces are tau = T^T qfrc_bias with T = [I; -C_free^+ C_act] (a serial chain: T = I).

Two loads per pose: the model's own masses, and a unit mass (1 kg) at the tool site, so that
an undeclared payload can be scanned (its mass is a shape parameter of the candidate). A model
whose masses MuJoCo defaulted (a kinematics-only MJCF) has no own weight to speak of: ``own``
is then zero (``payload_only``) and only the tool payload's load is known, whose mass the
candidate cannot separate from the compliance.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np

from common.worker_processes import map_chunks
from twin.kinematics.closure import closure_jacobian, update_kinematics
from twin.mechanism import Mechanism

STANDARD_GRAVITY = np.array([0.0, 0.0, -9.80665])


@dataclass(frozen=True)
class GravityLoads:
    own: np.ndarray  # (N, A) actuator force/torque holding the model's masses (N or N m)
    unit_payload: np.ndarray  # (N, A) the same for 1 kg at the tool site
    moving_mass_kg: float  # total mass of the bodies below the world
    payload_only: bool = False  # the model's masses are unknown: ``own`` is zero


def gravity_loads(mech: Mechanism, qpos: np.ndarray, payload_only: bool = False) -> GravityLoads:
    """Actuator loads of the model's masses and of a unit tool payload at each ``qpos``
    (``payload_only``: the masses are unknown, ``own`` is zero)."""
    model = copy.deepcopy(mech.model)
    g = np.asarray(model.opt.gravity, dtype=float)
    if np.linalg.norm(g) == 0:  # kinematics models run with gravity off: put it back
        g = STANDARD_GRAVITY
        model.opt.gravity[:] = g
    loaded = mech.with_model(model)
    m, d = loaded.model, loaded.data
    act, free = loaded.actuator_dofs, loaded.free_dofs()
    n_a = len(act)

    def loads_of(poses: np.ndarray) -> np.ndarray:
        """(own, unit) of each of these poses, (len, 2, A)."""
        out = np.empty((len(poses), 2, n_a))
        jacp = np.zeros((3, m.nv))
        bias = np.zeros(m.nv)
        for k, q in enumerate(qpos[poses]):
            update_kinematics(loaded, q)
            d.qvel[:] = 0.0
            mujoco.mj_rne(m, d, 0, bias)
            mujoco.mj_jacSite(m, d, jacp, None, loaded.tool_site)
            payload = jacp.T @ (-g)  # what the joints must supply to hold 1 kg at the tool
            t = np.zeros((m.nv, n_a))
            t[act, np.arange(n_a)] = 1.0
            if free.size:
                c = closure_jacobian(loaded)
                t[free] = -np.linalg.lstsq(c[:, free], c[:, act], rcond=None)[0]
            out[k, 0] = t.T @ bias
            out[k, 1] = t.T @ payload
        return out

    # the poses in chunks, side by side in worker processes on a long run (each pose's loads
    # those of one process, bit for bit: common.worker_processes)
    rows = 3 * len(loaded.target_names) * len(qpos)
    both = np.concatenate(list(map_chunks(loads_of, len(qpos), rows)))
    own, unit = both[:, 0], both[:, 1]
    if payload_only:
        return GravityLoads(np.zeros_like(own), unit, 0.0, payload_only=True)
    return GravityLoads(own, unit, float(np.sum(m.body_mass[1:])))
