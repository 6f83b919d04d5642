"""The picture of a verification: the 3D error of every pose before and after, its worst few
named, and the distributions.

It scales to thousands of poses: each side is one line of markers (not a bar per pose), the
pose_id of every pose is written on the axis only while they fit (``LABELLED_POSES``), and
beyond that only the worst few after calibration are named beside their markers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.fit import Verification
from common.atomic_files import write_figure_png

LABELLED_POSES = 40  # up to this many poses, each pose_id on the axis
WORST = 5  # beyond, the poses named beside their markers: the largest errors after


def verification_figure(v: Verification):
    """The matplotlib figure of ``v`` (the caller closes it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    before = v.before.per_reading_m.mean(axis=1) * 1e3
    after = v.after.per_reading_m.mean(axis=1) * 1e3
    n = len(before)
    idx = np.arange(n)
    fig, (ax, hx) = plt.subplots(1, 2, figsize=(11, 3.8), gridspec_kw={"width_ratios": [3, 1]})
    marker = {"ms": 4 if n <= 200 else 2, "ls": "none"}
    ax.plot(idx, before, "o", **marker, label=f"before (RMS {v.before.position.rms_mm:.3f} mm)")
    ax.plot(idx, after, "s", **marker, label=f"after (RMS {v.after.position.rms_mm:.3f} mm)")
    if n <= LABELLED_POSES:
        ax.set_xticks(idx, [str(p) for p in v.pose_ids], rotation=90, fontsize=6)
        ax.set_xlabel("pose_id")
    else:
        ax.set_xlabel(f"pose, in the file's order (the {WORST} worst after named by pose_id)")
        finite = np.where(np.isfinite(after), after, -np.inf)
        for k in np.argsort(-finite, kind="stable")[:WORST]:
            ax.annotate(
                str(v.pose_ids[k]),
                (idx[k], after[k]),
                xytext=(3, 3),
                textcoords="offset points",
                fontsize=7,
                color="C1",
            )
    ax.set_ylabel("3D position error (mm, log)")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.set_title(f"{v.n_poses} poses: 3D position error per pose (mean over its targets)")
    positive = np.concatenate([before, after])
    positive = positive[np.isfinite(positive) & (positive > 0)]
    lo = max(float(positive.min()), 1e-4) if positive.size else 1e-4
    hi = max(float(positive.max()), lo * 10) if positive.size else 1e-3
    bins = np.geomspace(lo, hi, 25)
    hx.hist(before, bins=bins, alpha=0.6, label="before")
    hx.hist(after, bins=bins, alpha=0.6, label="after")
    hx.set_xscale("log")
    hx.set_xlabel("3D position error per pose (mm)")
    hx.set_ylabel("poses")
    hx.set_title("distribution")
    fig.tight_layout()
    return fig


def save_verification_png(v: Verification, path: str | Path) -> Path:
    """:func:`verification_figure` written atomically."""
    return write_figure_png(verification_figure(v), path)
