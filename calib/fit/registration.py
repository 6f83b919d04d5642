"""The tracker in its own frame: the base-from-tracker transform, estimated with the machine.

A laser tracker reports in its own frame, often metres from the machine and turned by any
angle. With ``p_base = R p_tracker + t`` the six registration parameters are the translation
``t`` (the tracker's origin in the base frame) and a rotation increment ``phi`` with
``R = Exp(phi) R0``, from a starting rotation ``R0``. They start from a closed-form rigid fit
(Kabsch, via scipy's ``Rotation.align_vectors``) of the nominal predictions to the readings,
and are then estimated together with the kinematic parameters. The fit works on readings less
their centre (:func:`centred`): the rotation then turns about the readings, not about the
tracker's head metres away, whose lever arm would tie every rotation step to a translation
(a hexapod 4.5 m away needed 356 iterations instead of 88) and so the tracker's distance and
turn cost nothing; :func:`about` and :func:`about_jacobian` carry the result back.
They are never counted among the machine's errors; error-model parameters that the
registration makes redundant (a base offset, a base rotation) are reported as such.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.exceptions import CalibError
from twin.parameters import left_jacobian_so3
from twin.rotations import matrix_from_rotvec, rpy_from_matrix, skew

NAMES = (
    "registration.x",
    "registration.y",
    "registration.z",
    "registration.rx",
    "registration.ry",
    "registration.rz",
)
COLLINEAR_RTOL = 1e-3  # second singular value of the centred points against the first


class RegistrationError(CalibError):
    """The readings cannot fix the tracker's frame (too few, collinear, or no fit)."""


@dataclass(frozen=True)
class Registration:
    """base_from_tracker: ``p_base = rotation @ p_tracker + translation`` (metres)."""

    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)

    def to_base(self, points_tracker: np.ndarray) -> np.ndarray:
        return np.asarray(points_tracker, dtype=float) @ self.rotation.T + self.translation

    def to_tracker(self, points_base: np.ndarray) -> np.ndarray:
        return (np.asarray(points_base, dtype=float) - self.translation) @ self.rotation

    def moved(self, x: np.ndarray) -> Registration:
        """This registration moved by ``x`` = (t (3), phi (3)): t is absolute, phi turns it."""
        x = np.asarray(x, dtype=float)
        return Registration(matrix_from_rotvec(x[3:]) @ self.rotation, x[:3].copy())

    def start_vector(self) -> np.ndarray:
        """The parameter vector (t, phi = 0) of this registration as the start R0."""
        return np.concatenate([self.translation, np.zeros(3)])

    def as_dict(self, std: np.ndarray | None = None) -> dict:
        out = {
            "meaning": "p_base = R p_tracker + t; t is the tracker origin in the base frame",
            "translation_mm": (self.translation * 1e3).tolist(),
            "rotation_rpy_deg": np.degrees(rpy_from_matrix(self.rotation)).tolist(),
            "rotation_matrix": self.rotation.tolist(),
            "distance_mm": float(np.linalg.norm(self.translation) * 1e3),
        }
        if std is not None:
            out["std_translation_mm"] = (np.asarray(std[:3]) * 1e3).tolist()
            out["std_rotation_deg"] = np.degrees(np.asarray(std[3:])).tolist()
        return out

    @classmethod
    def from_dict(cls, data: dict) -> Registration:
        try:
            rot = np.array(data["rotation_matrix"], dtype=float)
            t = np.array(data["translation_mm"], dtype=float) * 1e-3
        except (KeyError, TypeError, ValueError) as exc:
            raise RegistrationError(f"registration entry is malformed: {exc}") from None
        if rot.shape != (3, 3) or t.shape != (3,):
            raise RegistrationError("registration needs a 3x3 rotation_matrix and 3 translation_mm")
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-9) or np.linalg.det(rot) < 0:
            raise RegistrationError("registration rotation_matrix is not a proper rotation")
        return cls(rot, t)


def identity() -> Registration:
    return Registration(np.eye(3), np.zeros(3))


def initial_registration(
    measured_tracker: np.ndarray, predicted_base: np.ndarray, keep: np.ndarray | None = None
) -> Registration:
    """Closed-form rigid fit of the nominal predictions (base) to the readings (tracker).

    ``keep`` (same leading shape, bool) leaves readings out. Raises RegistrationError when
    the points are too few or collinear, so that no rotation about their line is fixed."""
    m = np.asarray(measured_tracker, dtype=float).reshape(-1, 3)
    p = np.asarray(predicted_base, dtype=float).reshape(-1, 3)
    if keep is not None:
        k = np.asarray(keep, dtype=bool).reshape(-1)
        m, p = m[k], p[k]
    if len(m) < 3:
        raise RegistrationError(
            f"{len(m)} readings cannot fix the tracker's frame: at least 3 points not on a line "
            "are needed"
        )
    mc, pc = m - m.mean(axis=0), p - p.mean(axis=0)
    s = np.linalg.svd(pc, compute_uv=False)
    if s[0] <= 0 or s[1] < COLLINEAR_RTOL * s[0]:
        raise RegistrationError(
            "the measured points lie on a line: the rotation about it, and so the tracker's "
            "frame, cannot be found (measure poses that span a volume)"
        )
    from scipy.spatial.transform import Rotation  # lazy: scipy.spatial costs 0.5 s at import

    rot, _ = Rotation.align_vectors(pc, mc)
    r = rot.as_matrix()
    return Registration(r, p.mean(axis=0) - m.mean(axis=0) @ r.T)


def centred(measured_tracker: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The readings less their centre (the mean of every reading), and that centre."""
    m = np.asarray(measured_tracker, dtype=float)
    centre = m.reshape(-1, 3).mean(axis=0)
    return m - centre, centre


def about(reg_centred: Registration, centre: np.ndarray) -> Registration:
    """The registration of the readings themselves from that of the readings less
    ``centre``: the same rotation, the translation moved by it."""
    return Registration(
        reg_centred.rotation, reg_centred.translation - reg_centred.rotation @ np.asarray(centre)
    )


def about_jacobian(start: Registration, x: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """d(t, phi)/d(t_c, phi) (6, 6) of :func:`about` for the registration ``start.moved(x)``
    of centred readings (x = (t_c, phi)): what carries its covariance to the readings' frame."""
    x = np.asarray(x, dtype=float)
    rotated = matrix_from_rotvec(x[3:]) @ start.rotation @ np.asarray(centre, dtype=float)
    jac = np.eye(6)
    jac[:3, 3:] = skew(rotated) @ left_jacobian_so3(x[3:])
    return jac


def registration_jacobian(
    start: Registration, x: np.ndarray, measured_tracker: np.ndarray
) -> np.ndarray:
    """d(p_base)/d(x) for x = (t, phi), rows ordered as ``points.reshape(-1)``, (N*3, 6)."""
    x = np.asarray(x, dtype=float)
    q = (
        np.asarray(measured_tracker, dtype=float).reshape(-1, 3)
        @ (matrix_from_rotvec(x[3:]) @ start.rotation).T
    )
    jac = rigid_motion_span(q)  # the rotation increment turns about the tracker head
    jac[:, 3:] = jac[:, 3:] @ left_jacobian_so3(x[3:])
    return jac


def rigid_motion_span(points_base: np.ndarray) -> np.ndarray:
    """Columns (N*3, 6) spanning what a rigid motion of the frame does to ``points_base``:
    the registration's effect on noise-free model points, for identifiability."""
    p = np.asarray(points_base, dtype=float).reshape(-1, 3)
    jac = np.zeros((len(p), 3, 6))
    jac[:, :, :3] = np.eye(3)
    jac[:, :, 3:] = -skew(p)
    return jac.reshape(len(p) * 3, 6)


def project_out(jac: np.ndarray, reg_jac: np.ndarray) -> np.ndarray:
    """The kinematic columns with what the registration can do removed (for identifiability):
    a column that becomes zero is redundant with the registration."""
    q, _ = np.linalg.qr(reg_jac)
    return jac - q @ (q.T @ jac)
