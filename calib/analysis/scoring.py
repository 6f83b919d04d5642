"""Pose errors of the tool from tracker targets, and their statistics.

The measured tool pose is the rigid fit of the targets' known tool-frame positions to their
measured positions; the position error is the distance between measured and commanded
tool origins, the orientation error the angle of ``R_cmd^T R_meas``. Statistics follow the
second paper's tables: peak (largest), standard deviation (of the error magnitudes) and mean.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from twin.kinematics.single_pose import pose_to_frame
from twin.rigid_fit import fit_rigid_transform
from twin.rotations import rotation_angle


@dataclass(frozen=True)
class PoseErrors:
    position: np.ndarray  # (N,) metres
    orientation: np.ndarray  # (N,) radians
    position_vectors: np.ndarray  # (N, 3) measured - commanded, metres


@dataclass(frozen=True)
class ErrorStats:
    pos_peak_mm: float
    pos_mean_mm: float
    pos_std_mm: float
    pos_rms_mm: float
    ori_peak_deg: float
    ori_mean_deg: float
    ori_std_deg: float
    n_poses: int

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def pose_errors(
    commanded_poses: np.ndarray, measured_targets: np.ndarray, target_local: np.ndarray
) -> PoseErrors:
    """Errors of measured tool poses (from targets (N, T, 3)) against commanded poses (N, 6)."""
    r_cmd, p_cmd = pose_to_frame(commanded_poses)
    r_meas, p_meas = fit_rigid_transform(target_local, measured_targets)
    dp = p_meas - p_cmd
    angle = rotation_angle(np.swapaxes(r_cmd, -1, -2) @ r_meas)
    return PoseErrors(np.linalg.norm(dp, axis=-1), angle, dp)


def error_stats(errors: PoseErrors) -> ErrorStats:
    pos = errors.position * 1e3
    ori = np.degrees(errors.orientation)
    return ErrorStats(
        pos_peak_mm=float(pos.max()),
        pos_mean_mm=float(pos.mean()),
        pos_std_mm=float(pos.std(ddof=1)) if pos.size > 1 else 0.0,
        pos_rms_mm=float(np.sqrt(np.mean(pos**2))),
        ori_peak_deg=float(ori.max()),
        ori_mean_deg=float(ori.mean()),
        ori_std_deg=float(ori.std(ddof=1)) if ori.size > 1 else 0.0,
        n_poses=int(pos.size),
    )


def pose_errors_between(
    target_local: np.ndarray, reference_targets: np.ndarray, measured_targets: np.ndarray
) -> PoseErrors:
    """Errors of measured poses against reference poses, both fitted from targets (N, T, 3)
    (e.g. the pose a model predicts for the commands against the one the tracker saw)."""
    r_ref, p_ref = fit_rigid_transform(target_local, reference_targets)
    r_meas, p_meas = fit_rigid_transform(target_local, measured_targets)
    dp = p_meas - p_ref
    angle = rotation_angle(np.swapaxes(r_ref, -1, -2) @ r_meas)
    return PoseErrors(np.linalg.norm(dp, axis=-1), angle, dp)


def max_mean_stats(errors: PoseErrors) -> dict[str, float]:
    """Largest and mean position and orientation errors (the first paper's Table 5)."""
    pos = errors.position * 1e3
    ori = np.degrees(errors.orientation)
    return {
        "pos_max_mm": float(pos.max()),
        "pos_mean_mm": float(pos.mean()),
        "ori_max_deg": float(ori.max()),
        "ori_mean_deg": float(ori.mean()),
    }
