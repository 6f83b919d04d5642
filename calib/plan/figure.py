"""The figure of a prediction: held-out 3D error against the number of calibration poses, for
the plan and for random poses of the same pool (median and 90th percentile, the mean over the
draws with their standard deviation as error bars)."""

from __future__ import annotations

from pathlib import Path

from calib.plan.prediction import Prediction


def save_curve_png(curve: list[Prediction], path: str | Path, title: str) -> None:
    """Write the PNG to ``path`` (the caller makes it atomic)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    try:
        for kind, colour in (("plan", "tab:blue"), ("random", "tab:orange")):
            rows = [p.stats() for p in curve if p.kind == kind]
            n = [r["n"] for r in rows]
            for key, style, what in (("median_mm", "-o", "median"), ("p90_mm", "--s", "90th pct")):
                std = [r[key.replace("_mm", "_std_mm")] for r in rows]
                ax.errorbar(
                    n,
                    [r[key] for r in rows],
                    yerr=std,
                    fmt=style,
                    color=colour,
                    capsize=3,
                    label=f"{kind} poses, {what}",
                )
        ax.set_xlabel("calibration poses N")
        ax.set_ylabel("predicted held-out 3D error (mm)")
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=110, format="png")
    finally:
        plt.close(fig)
