"""Rotary encoder errors of a revolute joint: an eccentric and an oval graduated disc.

A joint's angle is read on a graduated disc (radius ``radius_m``) by one reading head. The
controller servos the joint until the angle it reads equals the command, so the joint really
stands where the *read* angle is the command.

* Eccentricity: the disc's centre sits ``eccentricity_m`` off the shaft axis, in a direction
  phi_i fixed on the disc. Turned by theta, the centre is at e (cos(theta + phi), sin(theta +
  phi)); the head, fixed at (R, 0), reads the graduation under it, so exactly

      read = theta + atan2(e sin(theta + phi), R - e cos(theta + phi))

  = theta + (e / R) sin(theta + phi) + (e / R)^2 / 2 sin(2 (theta + phi)) + ...: once per
  revolution in the main, every harmonic in the exact form.
* Ovality: a disc clamped out of round (or tilted on its hub, seen in projection) carries its
  graduation on an ellipse of axis ratio 1 - ``ovality``, its major axis at psi_i:

      read = psi + atan2((1 - o) sin(theta - psi), cos(theta - psi))

  = theta - (o / 2) sin(2 (theta - psi)) + ...: twice per revolution and its even harmonics.

theta is the joint's angle from its encoder zero (the joint zero of the MJCF). The phases are
drawn uniformly per joint (seeded) unless ``phases_rad`` gives them (A x 2 values,
actuator-major: phi, psi). Prismatic actuators are untouched.

Magnitudes: a hollow-shaft encoder disc mounted on its hub to 5-20 um with a 20-40 mm
graduation radius: e / R = 1e-4 to 1e-3 rad (20-200 arcsec); manufacturers of modular angle
encoders state the error of an eccentricity e at graduation radius R as +-e / R (e.g. 10 um on
a 60 mm diameter: +-69 arcsec). Default 10 um at 30 mm (3.3e-4 rad, 69 arcsec), no ovality;
an ovality of 1e-4 gives 5e-5 rad (10 arcsec) twice per revolution.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twin.effects._checks import finite, floats, seed
from twin.exceptions import ModelError
from twin.mechanism import Mechanism

ROUNDS = 30  # fixed-point rounds: the error is < 1e-2 of the angle's change, converges fast


@dataclass(frozen=True)
class EncoderEccentricity:
    eccentricity_m: float = 10e-6  # disc centre off the shaft axis
    radius_m: float = 0.03  # radius of the graduation
    ovality: float = 0.0  # 1 - axis ratio of the graduation's ellipse
    phases_rad: tuple[float, ...] = field(default=())  # A x 2 (phi, psi); () draws them
    seed: int = 0
    name: str = "encoder_eccentricity"

    def __post_init__(self) -> None:
        finite(self.eccentricity_m, "eccentricity_m", min=0.0)
        finite(self.radius_m, "radius_m", above=0.0)
        finite(self.ovality, "ovality", min=0.0)
        if self.eccentricity_m >= 0.1 * self.radius_m or self.ovality >= 0.1:
            raise ValueError(
                "encoder_eccentricity: an eccentricity of 10 % of the radius or an ovality of "
                f"0.1 is no encoder, got e = {self.eccentricity_m!r} m at R = "
                f"{self.radius_m!r} m, ovality {self.ovality!r}"
            )
        object.__setattr__(self, "phases_rad", floats(self.phases_rad, "phases_rad"))
        seed(self.seed)

    def phases(self, mech: Mechanism) -> np.ndarray:
        """(A, 2): phi (eccentricity direction) and psi (major axis) of each joint's disc."""
        n = mech.n_actuators
        if not self.phases_rad:
            return np.random.default_rng(self.seed).uniform(0.0, 2 * np.pi, (n, 2))
        if len(self.phases_rad) != 2 * n:
            raise ModelError(
                f"encoder_eccentricity needs 2 x {n} phases for {mech.actuator_names}, "
                f"got {len(self.phases_rad)}"
            )
        return np.reshape(self.phases_rad, (n, 2))

    def read(self, mech: Mechanism, theta: np.ndarray) -> np.ndarray:
        """The angle the encoder reads (N, A) at true joint angles ``theta`` from its zero."""
        ph = self.phases(mech)
        phi, psi = ph[None, :, 0], ph[None, :, 1]
        e, r, o = self.eccentricity_m, self.radius_m, self.ovality
        out = theta + np.arctan2(e * np.sin(theta + phi), r - e * np.cos(theta + phi))
        if o:
            u = theta - psi
            out = out + (
                np.arctan2((1 - o) * np.sin(u), np.cos(u)) - np.arctan2(np.sin(u), np.cos(u))
            )
        return out

    def apply(self, mech: Mechanism, commands: np.ndarray, order: np.ndarray) -> np.ndarray:
        hinge = ~np.asarray(mech.actuator_is_slide, bool)
        if not np.any(hinge):
            raise ModelError(
                f"encoder_eccentricity: '{mech.name}' has no revolute actuator to read"
            )
        if self.eccentricity_m == 0.0 and self.ovality == 0.0:
            return commands
        zero = mech.model.qpos0[mech.actuator_qpos][None, :]
        target = np.asarray(commands, dtype=float) - zero
        theta = target.copy()
        for _ in range(ROUNDS):  # the joint stands where the read angle is the command
            theta = target - (self.read(mech, theta) - theta)
        return np.where(hinge[None, :], zero + theta, commands)
