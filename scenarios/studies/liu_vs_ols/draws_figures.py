"""The draw study's figure: (estimator - OLS) test-layer mean and max error over the draws,
in mm (as every figure)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from scenarios.figures import plt, save_png
from scenarios.studies.liu_vs_ols.report import shown


def draws_figure(out_dir: Path, results: list[dict[str, Any]], labels: list[str]) -> dict[str, str]:
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.4))
    for ax, q, what in zip(axes, ("pos_mean_mm", "pos_max_mm"), ("mean", "max"), strict=True):
        ols = np.array([r["layers"]["test"]["ols"][q] for r in results])
        for lab in labels:
            diff = np.array([r["layers"]["test"][lab][q] for r in results]) - ols
            ax.hist(
                diff,
                bins=25,
                alpha=0.6,
                label=f"{shown(lab)} (median {np.median(diff):+.4f})",
            )
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_xlabel(f"estimator - OLS, test layer {what} error (mm)", fontsize=10)
        ax.set_ylabel("draws", fontsize=10)
        ax.legend(fontsize=8)
    fig.suptitle(
        f"polisher, {len(results)} truth draws: below 0 the estimator beats OLS", fontsize=11
    )
    fig.tight_layout()
    save_png(fig, out_dir / "draws_liu_minus_ols.png")
    return {"draws_liu_minus_ols": "draws_liu_minus_ols.png"}
