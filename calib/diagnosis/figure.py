"""The residual of a diagnosis plotted against the variable that explains it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common.atomic_files import write_figure_png


def save_diagnosis_png(diag, path: str | Path) -> Path:
    """Per-pose residual size (RMS over its rows, mm) against the explaining variable,
    before and (for a named effect) after the correction; above it, for an actuator effect,
    the actuator's offset seen in each pose's readings against the fitted one (the shape of
    the effect itself). Lengths in mm, angles in deg (calib.diagnosis.plot); text of 10-11
    points on 6.4 x 4.2-5 inches, to be read in a view of about 700 x 420 pixels. Written
    atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plot = diag.plot
    x = np.asarray(plot["x"], dtype=float)
    partial = plot.get("partial")
    if partial is None:
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
    else:
        fig, (top, ax) = plt.subplots(
            2, 1, figsize=(6.4, 5.0), sharex=True, gridspec_kw={"height_ratios": [1, 1.4]}
        )
        order = np.argsort(x)
        top.plot(x, partial["seen"], "o", ms=4, color="#4c78a8", label="seen in the readings")
        top.plot(
            x[order],
            np.asarray(partial["fitted"])[order],
            "-",
            color="#e45756",
            lw=1.2,
            label=f"{diag.chosen.split('+')[0]} fitted",
        )
        top.axhline(0.0, color="k", lw=0.6)
        top.set_ylabel(partial["label"], fontsize=11)
        top.set_title(f"diagnosis: {diag.chosen}", fontsize=11)
        top.legend(fontsize=10)
        top.tick_params(labelsize=10)
    ax.plot(x, plot["before_mm"], "o", ms=4, label="geometric fit only")
    if plot["after_mm"] is not None:
        ax.plot(x, plot["after_mm"], "s", ms=4, label=f"with {diag.chosen}")
    ax.axhline(diag.noise_floor_rms_mm, color="k", lw=0.8, ls="--", label="noise per coordinate")
    ax.set_xlabel(plot["variable"], fontsize=11)
    ax.set_ylabel("residual per pose, RMS\nper coordinate (mm)", fontsize=11)
    if partial is None:
        ax.set_title(f"diagnosis: {diag.chosen}", fontsize=11)
    ax.legend(fontsize=10)
    ax.tick_params(labelsize=10)
    fig.tight_layout()
    return write_figure_png(fig, path)
