"""Orientation rows of 6-DoF probe readings, beside the position rows of every target.

A probe reading carries the rotation ``M`` of the target's frame in the reading's frame. Its
residual is the rotation vector ``w log(R_reg M R_pred^T)`` (world axes, the base frame),
with ``R_reg`` the registration's rotation (identity for base-frame readings) and ``R_pred``
the model's target frame. The weight ``w = sigma_position / sigma_orientation`` (metres per
radian, from the declared accuracies: ``tracker.sigma_mm`` and ``tracker.sigma_deg``) puts
an orientation row on the scale of a position row, so that one fit, one robust scale and one
covariance serve both. Each probe's three orientation rows form one more "reading" of its
pose, after the pose's position readings: the outlier screen rejects an orientation as it
rejects a point.

Gauss-Newton derivatives (first order in the small residual): a parameter turns the target's
frame by the angular part of the tool's error twist (the probe sits on the tool's body), so
d r / d x = -w J_angular; the registration's rotation increment phi turns the reading, so
d r / d phi = w J_l(phi) (the left Jacobian its position rows use), and its translation
leaves it alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from calib.data.dataset import DatasetError
from twin.mechanism import Mechanism
from twin.parameters import left_jacobian_so3
from twin.rotations import rotvec_from_matrix


def orientation_weight(sigma_mm: float, tracker: dict | None) -> float:
    """w = sigma_position / sigma_orientation (m / rad) from the declared accuracies."""
    value = (tracker or {}).get("sigma_deg")
    if value is None:
        raise DatasetError(
            "the readings carry orientations (qw,qx,qy,qz) but the sidecar declares no "
            "tracker.sigma_deg: the probe's orientation accuracy (deg per axis) weighs its "
            "orientation rows against the positions"
        )
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise DatasetError(f"the sidecar's tracker.sigma_deg must be a number > 0, got {value!r}")
    return sigma_mm * 1e-3 / np.radians(float(value))


def target_rotations(mech: Mechanism, qpos: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """The frames (P, K, 3, 3) of target indices ``targets`` at configurations ``qpos``."""
    data = mujoco.MjData(mech.model)
    sites = mech.target_sites[np.asarray(targets, dtype=int)]
    out = np.empty((len(qpos), len(sites), 3, 3))
    for p, q in enumerate(np.atleast_2d(qpos)):
        data.qpos[:] = q
        mujoco.mj_kinematics(mech.model, data)
        out[p] = data.site_xmat[sites].reshape(-1, 3, 3)
    return out


@dataclass(frozen=True)
class ProbeRows:
    """The oriented targets' measured frames and the weight of their rows."""

    targets: np.ndarray  # (K,) indices of the oriented targets
    measured: np.ndarray  # (P, K, 3, 3) in the readings' frame
    weight: float  # metres per radian

    @classmethod
    def of(cls, mech: Mechanism, rotations: np.ndarray | None, weight: float | None):
        """None without orientations; raises for a probe off the tool's body."""
        if rotations is None:
            return None
        oriented = np.flatnonzero(np.isfinite(rotations).all(axis=(0, 2, 3)))
        if not oriented.size:
            return None
        if weight is None:
            raise DatasetError("orientation readings need an orientation accuracy (sigma_deg)")
        body = mech.model.site_bodyid
        off = [
            mech.target_names[t]
            for t in oriented
            if body[mech.target_sites[t]] != body[mech.tool_site]
        ]
        if off:
            raise DatasetError(
                f"target(s) {off} carry an orientation but do not sit on the tool's body: "
                "their frame would not follow the tool's (leave their qw..qz empty)"
            )
        return cls(oriented, np.asarray(rotations)[:, oriented], float(weight))

    @property
    def n(self) -> int:
        return len(self.targets)

    def residual(self, mech: Mechanism, qpos: np.ndarray, reg_rotation: np.ndarray | None):
        """(P, K, 3): w log(R_reg M R_pred^T)."""
        pred = target_rotations(mech, qpos, self.targets)
        meas = self.measured if reg_rotation is None else reg_rotation @ self.measured
        return self.weight * rotvec_from_matrix(meas @ np.swapaxes(pred, -1, -2))

    def jacobian(
        self, angular: np.ndarray, phi: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """d residual / d (parameters) (P, K*3, n) from the tool's angular rows (P, 3, n), and
        d residual / d (registration) (P, K*3, 6) when there is one (``phi`` its increment)."""
        p = len(angular)
        par = np.tile(-self.weight * angular, (1, self.n, 1))
        if phi is None:
            return par, None
        reg = np.zeros((p, self.n, 3, 6))
        reg[:, :, :, 3:] = self.weight * left_jacobian_so3(np.asarray(phi, dtype=float))
        return par, reg.reshape(p, self.n * 3, 6)

    def registration_span(self, n_poses: int) -> np.ndarray:
        """What a rigid motion of the frame does to these rows (P, K*3, 6), for identifiability."""
        span = np.zeros((n_poses, self.n, 3, 6))
        span[:, :, :, 3:] = self.weight * np.eye(3)
        return span.reshape(n_poses, self.n * 3, 6)


def interleave(position: np.ndarray, orientation: np.ndarray, n_poses: int) -> np.ndarray:
    """Rows per pose: the pose's position rows, then its orientation rows. ``position`` is
    (P*T*3, c) or (P*T*3,), ``orientation`` (P, K*3, c) or (P, K, 3)."""
    if position.ndim == 1:
        return np.concatenate(
            [position.reshape(n_poses, -1), orientation.reshape(n_poses, -1)], axis=1
        ).reshape(-1)
    c = position.shape[1]
    return np.concatenate(
        [position.reshape(n_poses, -1, c), orientation.reshape(n_poses, -1, c)], axis=1
    ).reshape(-1, c)


def probe_line(obs, sigma_mm: float, sigma_deg: float, values_deg: np.ndarray | None) -> str:
    """What identify says of the probes' rows, from their numbers: how many, their weight,
    and the orientation residual per pose (``values_deg``, RMS over the probes)."""
    oriented = np.isfinite(obs.rotations).all(axis=(0, 2, 3))
    names = [n for n, o in zip(obs.target_names or (), oriented, strict=False) if o]
    text = (
        f"6-DoF readings of {', '.join(names) or f'{int(oriented.sum())} target(s)'}: "
        f"orientation rows beside the positions, weighed {sigma_mm:g} mm / {sigma_deg:g} deg "
        f"= {obs.orientation_weight_m * 1e3:.2f} mm per rad"
    )
    if values_deg is not None:
        text += f"; orientation residual RMS {np.sqrt(np.mean(values_deg**2)):.4f} deg"
    return text
