"""Thermal warm-up: the structure grows with a temperature that rises in time.

A machine switched on warms with its drives, motors and spindle; the structure's temperature
above the one its nominal geometry holds at (20 C) follows a first-order warm-up

    dT(t) = start_K + delta_K (1 - exp(-t / tau_s)),    t = start_s + k * seconds_per_pose

for the k-th pose in measurement order. Every chosen body grows by the linear expansion
e = alpha dT about its parent frame: its position in the parent (``body_pos``: link lengths,
the base's joint circle when the parent is the world), the joints' anchors and the sites on
it (platform joint circle, tool offset, reflectors) scale by 1 + e; orientations stay. A
prismatic actuator on a grown body also travels (1 + e) times as far from its joint zero
(the screw grows with the rest). Serial and closed chains alike: with every body chosen the
whole machine is similar to the cold one, scaled by 1 + e about the world origin.

Magnitudes: steel alpha = 11.5e-6 / K, aluminium 23e-6 / K, cast iron 10.5e-6 / K. Machine
tools and robots warm by 2-5 K in their structure over the first hour (ISO 230-3 thermal
tests; spindle and drive warm-up time constants of 20-60 min are the rule); defaults: 3 K,
tau = 30 min, 30 s per pose (80 poses, 40 min: 74 % of the rise). A 1 m steel arm then grows
35 um, the 0.23 m legs of the small hexapod 8 um.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from fnmatch import fnmatchcase

import mujoco
import numpy as np

from twin.effects._checks import finite
from twin.exceptions import ModelError
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class ThermalWarmup:
    delta_K: float = 3.0  # final rise of the structure during the warm-up
    tau_s: float = 1800.0  # warm-up time constant
    start_K: float = 0.0  # the structure above 20 C at t = 0 (a warm hall: 1-3 K)
    seconds_per_pose: float = 30.0  # measurement time per pose (move, settle, read targets)
    start_s: float = 0.0  # time since switch-on at the first pose
    alpha_per_K: float = 11.5e-6  # steel
    bodies: str = "*"  # comma-separated name patterns (fnmatch) of the bodies that grow
    name: str = "thermal_warmup"

    def __post_init__(self) -> None:
        finite(self.delta_K, "delta_K")
        finite(self.tau_s, "tau_s", above=0.0)
        finite(self.start_K, "start_K")
        finite(self.seconds_per_pose, "seconds_per_pose", min=0.0)
        finite(self.start_s, "start_s", min=0.0)
        finite(self.alpha_per_K, "alpha_per_K", min=0.0)
        if not isinstance(self.bodies, str) or not self._patterns():
            raise ValueError(
                f"bodies must name body patterns like '*' or 'leg*,platform', got {self.bodies!r}"
            )

    def _patterns(self) -> list[str]:
        return [p.strip() for p in str(self.bodies).split(",") if p.strip()]

    def time_s(self, k: np.ndarray | int) -> np.ndarray:
        return self.start_s + self.seconds_per_pose * np.asarray(k, dtype=float)

    def temperature_K(self, t_s: np.ndarray | float) -> np.ndarray:
        """Rise of the structure above 20 C at time ``t_s`` (seconds since switch-on)."""
        t = np.asarray(t_s, dtype=float)
        return self.start_K + self.delta_K * -np.expm1(-t / self.tau_s)

    def strain(self, k: np.ndarray | int) -> np.ndarray:
        """Linear expansion alpha dT at the k-th pose of the sequence."""
        return self.alpha_per_K * self.temperature_K(self.time_s(k))

    def grown_bodies(self, mech: Mechanism) -> np.ndarray:
        m = mech.model
        names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or "" for b in range(m.nbody)]
        pats = self._patterns()
        ids = [b for b in range(1, m.nbody) if any(fnmatchcase(names[b], p) for p in pats)]
        if not ids:
            raise ModelError(
                f"thermal_warmup: no body of '{mech.name}' matches bodies={self.bodies!r}; "
                f"bodies: {names[1:]}"
            )
        return np.array(ids, dtype=int)

    def model_at(self, mech: Mechanism, k: int) -> Mechanism:
        e = float(self.strain(k))
        if e == 0.0:
            return mech
        grown = self.grown_bodies(mech)
        model = copy.deepcopy(mech.model)
        model.body_pos[grown] *= 1.0 + e
        joints = np.isin(model.jnt_bodyid, grown)
        model.jnt_pos[joints] *= 1.0 + e
        sites = np.isin(model.site_bodyid, grown)
        model.site_pos[sites] *= 1.0 + e
        mujoco.mj_setConst(model, mujoco.MjData(model))
        return mech.with_model(model)

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        """The screws of prismatic actuators on grown bodies travel (1 + e) times as far."""
        m = mech.model
        body = m.jnt_bodyid[mech.actuator_joints]
        screw = mech.actuator_is_slide & np.isin(body, self.grown_bodies(mech))
        if not np.any(screw):
            return commands
        e = self.strain(np.asarray(order))[:, None]
        zero = m.qpos0[mech.actuator_qpos][None, :]
        grown = np.where(e == 0.0, commands, zero + (commands - zero) * (1.0 + e))
        return np.where(screw[None, :], grown, commands)
