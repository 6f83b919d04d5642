"""The picture of a verification: the 3D error of every reading before and after."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.fit import Verification
from common.atomic_files import write_with_atomic


def save_verification_png(v: Verification, path: str | Path) -> Path:
    """Per-pose bars of the 3D error (mean over the pose's targets), before and after, and
    their distributions; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    before = v.before.per_reading_m.mean(axis=1) * 1e3
    after = v.after.per_reading_m.mean(axis=1) * 1e3
    idx = np.arange(len(before))
    fig, (ax, hx) = plt.subplots(1, 2, figsize=(11, 3.8), gridspec_kw={"width_ratios": [3, 1]})
    ax.bar(idx - 0.2, before, 0.4, label=f"before (RMS {v.before.position.rms_mm:.3f} mm)")
    ax.bar(idx + 0.2, after, 0.4, label=f"after (RMS {v.after.position.rms_mm:.3f} mm)")
    ax.set_xticks(idx, [str(p) for p in v.pose_ids], rotation=90, fontsize=6)
    ax.set_xlabel("pose_id")
    ax.set_ylabel("3D position error (mm)")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.set_title(f"{v.n_poses} poses: 3D position error per pose (mean over its targets)")
    bins = np.geomspace(max(min(before.min(), after.min()), 1e-4), max(before.max(), 1e-3), 25)
    hx.hist(before, bins=bins, alpha=0.6, label="before")
    hx.hist(after, bins=bins, alpha=0.6, label="after")
    hx.set_xscale("log")
    hx.set_xlabel("mm")
    hx.set_title("distribution")
    fig.tight_layout()
    try:
        return write_with_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    finally:
        plt.close(fig)
