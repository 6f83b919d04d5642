"""The loop's test set in one figure: each pose's 3D error under the nominal model, the
geometry identified, and the geometry with the named effect (verify's two files), beside the
tracker's accuracy. One panel, sized for a view of about 700 x 450 pixels: the two figures of
verify, each 11 inches wide with a histogram beside, were unreadable side by side."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from scenarios.figures import plt, save_png


def per_pose_mm(path: Path, column: str) -> np.ndarray:
    """``column`` of a verify CSV (one row per pose and target, mm), each pose's mean over
    its targets, the poses in the file's order."""
    by_pose: dict[str, list[float]] = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            by_pose.setdefault(row["pose_id"], []).append(float(row[column]))
    return np.array([np.mean(v) for v in by_pose.values()])


def test_errors_png(
    path: Path, stages: dict[str, tuple[np.ndarray, float]], accuracy_3d_mm: float
) -> Path:
    """Each stage's per-pose error (label -> (per pose mm, RMS per reading mm)) on a log
    axis, and the tracker's 3D accuracy as a dashed line."""
    fig, ax = plt.subplots(figsize=(6.4, 4.6), layout="constrained")
    for (label, (values, rms)), marker in zip(stages.items(), "o^s", strict=False):
        ax.plot(
            np.arange(len(values)),
            values,
            marker,
            ms=4,
            ls="none",
            label=f"{label} (RMS {rms:.3f} mm)",
        )
    ax.axhline(
        accuracy_3d_mm,
        color="k",
        lw=1.0,
        ls="--",
        label=f"tracker accuracy, 3D: {accuracy_3d_mm:.4f} mm",
    )
    ax.set_yscale("log")
    ax.set_xlabel("test pose, in the file's order", fontsize=11)
    ax.set_ylabel("3D position error per pose (mm, log)", fontsize=11)
    ax.tick_params(labelsize=10)
    n = len(next(iter(stages.values()))[0]) if stages else 0
    ax.set_title(f"test set, {n} poses: the error at each step of the loop", fontsize=11)
    fig.legend(fontsize=10, loc="outside lower center", ncol=2, frameon=False)
    return save_png(fig, path)
