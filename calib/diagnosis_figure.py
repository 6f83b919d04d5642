"""The residual of a diagnosis plotted against the variable that explains it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.atomic_files import write_with_atomic


def save_diagnosis_png(diag, path: str | Path) -> Path:
    """Per-pose residual size (RMS over its rows, mm) against the explaining variable,
    before and (for a named effect) after the correction; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plot = diag.plot
    x = np.asarray(plot["x"], dtype=float)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(x, plot["before_mm"], "o", ms=4, label="geometric fit only")
    if plot["after_mm"] is not None:
        ax.plot(x, plot["after_mm"], "s", ms=4, label=f"with {diag.chosen}")
    ax.axhline(diag.noise_floor_rms_mm, color="k", lw=0.8, ls="--", label="noise per coordinate")
    ax.set_xlabel(plot["variable"])
    ax.set_ylabel("residual per pose, RMS per coordinate (mm)")
    ax.set_title(f"diagnosis: {diag.chosen}", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    try:
        write_with_atomic(path, lambda f: fig.savefig(f, format="png", dpi=110))
    finally:
        plt.close(fig)
    return path
