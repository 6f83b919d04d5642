"""What the loop-closing scenarios log: each pose's residual before and after the named
effects were added (arrows on the machine, and against the measurement order), one figure per
named effect against the variable that explains it (scenarios.loop_figures), the candidates'
held-out errors by name, and the verdict as text."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from scenarios.recording.targets import arrow_scale

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
) -> None:
    """Poses by measurement order with the residual arrows before and after (both magnified
    by the same factor, chosen for the residual before), and both residuals as points
    against the order."""
    order = np.asarray(order, dtype=int)
    scale = arrow_scale(prediction.targets, measured)
    groups = {"geometry only": prediction.targets, "with the named effect": after}
    for group, predicted in groups.items():
        rec.log_poses(
            ORDER_TIMELINE, order, mech, prediction.qpos, predicted, measured, group, scale
        )
    before_mm = per_pose_mm(measured, prediction.targets)
    after_mm = per_pose_mm(measured, after)
    for k, b, a in zip(order, before_mm, after_mm, strict=True):
        rec.log_points("residual_mm/geometry_only", ORDER_TIMELINE, k, b)
        rec.log_points("residual_mm/with_named_effect", ORDER_TIMELINE, k, a)


def log_causes(
    rec: Any,
    diag: Any,
    figure: Path | None,
    plots: list[Any],
    noise_mm: float,
) -> None:
    """One view per named effect: the diagnosis's figure (``figure``, the report's) for the
    first, a figure of ``plots`` (loop_figures.effect_plots) for each further one; then the
    candidates' held-out RMS over the noise, by name."""
    from scenarios.loop_figures import effect_png, heldout_png

    named = [p.effect for p in plots]
    for k, plot in enumerate(plots):
        title = f"{plot.effect}: residual by {plot.variable}"
        if k == 0 and figure is not None and Path(figure).is_file():
            rec.log_figure(f"cause_{plot.effect}", figure, f"{plot.effect}: the diagnosis figure")
        else:
            others = [n for n in named if n != plot.effect]
            rec.log_figure(f"cause_{plot.effect}", effect_png(plot, noise_mm, others), title)
    if not plots and figure is not None and Path(figure).is_file():
        rec.log_figure("cause", figure, f"diagnosis: {diag.chosen}")
    ratio = {n: sc.heldout_rms_mm / diag.noise_floor_rms_mm for n, sc in diag.scores.items()}
    if ratio:
        rec.log_figure("heldout", heldout_png(ratio, diag.chosen), "candidates held out")


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
