"""What the loop-closing scenarios log: each pose's residual before and after the named effect
was added, against the measurement order, and the verdict as text."""

from __future__ import annotations

from typing import Any

import numpy as np

ORDER_TIMELINE = "measurement_order"


def per_pose_mm(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """The mean 3D target error of each pose (P, T, 3) -> (P,), in mm."""
    return np.linalg.norm(np.asarray(measured) - np.asarray(predicted), axis=-1).mean(axis=1) * 1e3


def log_loop(
    rec: Any,
    mech: Any,
    order: np.ndarray,
    prediction: Any,
    measured: np.ndarray,
    after: np.ndarray,
    scale: float = 1000.0,
) -> None:
    """Poses by measurement order with the residual arrows before and after (magnified
    ``scale``x), and both residuals as points against the order."""
    order = np.asarray(order, dtype=int)
    groups = {
        "geometry only (residual x1000)": prediction.targets,
        "with the named effect (residual x1000)": after,
    }
    for group, predicted in groups.items():
        rec.log_poses(
            ORDER_TIMELINE, order, mech, prediction.qpos, predicted, measured, group, scale
        )
    before_mm = per_pose_mm(measured, prediction.targets)
    after_mm = per_pose_mm(measured, after)
    for k, b, a in zip(order, before_mm, after_mm, strict=True):
        rec.log_points("residual_mm/geometry_only", ORDER_TIMELINE, k, b)
        rec.log_points("residual_mm/with_named_effect", ORDER_TIMELINE, k, a)


def verdict_markdown(diag: Any, before_mm: float, after_mm: float, noise_mm: float) -> str:
    structure = ", ".join(f"{k} {v:+.2f}" for k, v in (diag.structure or {}).items())
    return "\n".join(
        [
            f"## Verdict: **{diag.chosen}**",
            "",
            f"{diag.reason}.",
            "",
            "| residual (RMS per coordinate) | mm |",
            "|---|---|",
            f"| geometric calibration only | {before_mm:.4f} |",
            f"| with {diag.chosen} added | {after_mm:.4f} |",
            f"| tracker noise floor | {noise_mm:.4f} |",
            "",
            f"chi-square p of the geometric residual = {diag.chi2_p_value:.3g}",
            "",
            f"Rank correlation of each pose's residual with: {structure}",
        ]
    )
