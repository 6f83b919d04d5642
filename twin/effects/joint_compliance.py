"""Compliance of revolute joints under gravity: the gear winds up under the gravity torque.

A joint driven through a harmonic drive or another reducer is a torsional spring between
motor and link: holding the arm still under gravity, it carries the static gravity torque
tau and the link lags the motor by tau / k. tau comes from MuJoCo: ``qfrc_bias`` with gravity
on and the machine at rest (the real masses of the MJCF plus ``payload_kg`` at the tool
point), split into closure and actuator forces for a closed chain (as ``gravity_compliance``
does). The deflected joints change the pose and the torque, so the joint values are a fixed
point q = q_cmd - tau(q) / k (a few rounds).

Magnitudes: the torsional stiffness of harmonic drives (Harmonic Drive CSG/CSF catalogues,
K3 in the upper torque range) is about 1e4 N m/rad for size 20, 3e4 for size 25, 5e4 for size
32, 1e5 for size 40; a 1 m arm's shoulder carries a size 25-40 gear: default 5e4 N m/rad.
Default payload 5 kg (a spindle, gripper or reflector adaptor of a 6-10 kg class arm): about
45 N m at a 0.9 m reach, 0.9 mrad, 0.8 mm at the tool through the shoulder alone.

Prismatic actuators are rigid (``stiffness_N_per_m = inf``) unless a stiffness is given.
On a model with defaulted masses only the payload loads the machine (see
``gravity_compliance``); without one the effect raises ModelError.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.effects._checks import finite
from twin.effects.gravity_compliance import gravity_model, static_deflection
from twin.exceptions import ModelError
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class JointCompliance:
    stiffness_Nm_per_rad: float = 5e4  # harmonic drive, size ~32
    stiffness_N_per_m: float = math.inf  # prismatic actuators: rigid unless given
    payload_kg: float = 5.0  # at the tool point
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    max_rounds: int = 10
    name: str = "joint_compliance"

    def __post_init__(self) -> None:
        finite(self.stiffness_Nm_per_rad, "stiffness_Nm_per_rad", above=0.0)
        if not float(self.stiffness_N_per_m) > 0.0:
            raise ValueError(
                f"stiffness_N_per_m must be > 0 (inf: rigid), got {self.stiffness_N_per_m!r}"
            )
        finite(self.payload_kg, "payload_kg", min=0.0)
        if len(self.gravity) != 3:
            raise ValueError(f"gravity must be 3 numbers (m/s^2), got {self.gravity!r}")
        if int(self.max_rounds) < 1:
            raise ValueError(f"max_rounds must be >= 1, got {self.max_rounds!r}")

    def stiffness(self, mech: Mechanism) -> np.ndarray:
        k = np.where(
            mech.actuator_is_slide, float(self.stiffness_N_per_m), float(self.stiffness_Nm_per_rad)
        )
        if np.all(np.isinf(k)):
            raise ModelError(
                f"joint_compliance: '{mech.name}' has no revolute actuator and its prismatic "
                "ones are rigid; give stiffness_N_per_m (or use gravity_compliance)"
            )
        return k

    def loaded(self, mech: Mechanism) -> Mechanism:
        """The machine with gravity on and the payload's mass at the tool point."""
        model = gravity_model(mech, tuple(self.gravity), self.payload_kg, self.name)
        b, m_p = mech.tool_body, float(self.payload_kg)
        m_b = float(model.body_mass[b])
        if m_p > 0.0:
            tool = model.site_pos[mech.tool_site]  # in the tool body's frame
            model.body_ipos[b] = (m_b * model.body_ipos[b] + m_p * tool) / (m_b + m_p)
            model.body_mass[b] = m_b + m_p
        heavy = mech.with_model(model)
        return heavy

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        k = self.stiffness(mech)
        return static_deflection(self.loaded(mech), commands, k, int(self.max_rounds))
