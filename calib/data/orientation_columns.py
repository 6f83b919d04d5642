"""A target's orientation in a Dataset: the optional columns ``qw,qx,qy,qz``.

A 6-DoF probe (a T-Mac, a T-Probe) reports its frame as well as its point: the unit
quaternion (w first) of the target's frame in the reading's frame (the tracker's or the
base's, as the sidecar's ``frame`` says). A row of a target without orientation (a bare
reflector beside a probe) leaves the four cells empty; a target has an orientation at every
row or at none. Rotation vectors and Euler angles are refused: their axis orders and
conventions differ from one tracker's software to the next, the quaternion's does not. The
orientation accuracy is the sidecar's ``tracker.sigma_deg`` (per axis, degrees).
"""

from __future__ import annotations

import re

import numpy as np

from calib.data.dataset import DatasetError
from twin.rotations import matrix_from_quat

QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
UNIT_TOLERANCE = 1e-6  # |q| - 1 beyond this is no unit quaternion (exports print >= 9 digits)
_ROTATION_LIKE = re.compile(
    r"^(r[xyz]|[abc]|roll|pitch|yaw|rot(ation)?(vec)?_?[xyz]?|euler_?[a-z0-9]*|"
    r"[xyz]?rot|theta_?[xyz]|phi|psi|omega_?[xyz]?)(_deg|_rad|_mrad)?$",
    re.IGNORECASE,
)


def refuse_rotation_columns(path: object, header: list[str]) -> None:
    """Raise on orientation columns other than the quaternion, and on a partial quaternion."""
    bad = [h for h in header if _ROTATION_LIKE.match(h)]
    if bad:
        raise DatasetError(
            f"{path}: orientation column(s) {bad}: a target's orientation is given as the unit "
            "quaternion of its frame in the reading's frame, columns qw,qx,qy,qz (w first); "
            "rotation vectors and Euler angles are refused, their conventions differ between "
            "trackers' software (convert them to a quaternion in the export)"
        )
    present = [c for c in QUAT_COLUMNS if c in header]
    if present and len(present) < 4:
        missing = [c for c in QUAT_COLUMNS if c not in header]
        raise DatasetError(f"{path}: quaternion column(s) {missing} missing beside {present}")


def parse_quaternion(loc: str, cells: list[str]) -> list[float] | None:
    """The four cells of a row as a unit quaternion, or None when all four are empty."""
    if all(not c for c in cells):
        return None
    if any(not c for c in cells):
        raise DatasetError(f"{loc}: columns qw,qx,qy,qz must be all given or all empty")
    try:
        q = [float(c) for c in cells]
    except ValueError:
        raise DatasetError(f"{loc}: columns qw,qx,qy,qz must be numbers, got {cells}") from None
    norm = float(np.linalg.norm(q))
    if not np.isfinite(norm) or abs(norm - 1.0) > UNIT_TOLERANCE:
        raise DatasetError(
            f"{loc}: qw,qx,qy,qz = {cells} is no unit quaternion (norm {norm:.9g}); give the "
            "unit quaternion of the target's frame"
        )
    return [v / norm for v in q]


def mean_rotation(quats: np.ndarray) -> np.ndarray:
    """The chordal mean (..., 3, 3) of unit quaternions (..., R, 4): the rotation nearest the
    mean of their matrices (its SVD projection), order- and sign-independent."""
    mats = matrix_from_quat(np.asarray(quats, dtype=float)).mean(axis=-3)
    u, _, vt = np.linalg.svd(mats)
    d = np.sign(np.linalg.det(u @ vt))
    u[..., :, -1] *= d[..., None]
    return u @ vt
