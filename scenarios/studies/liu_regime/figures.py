"""The regime map's figures: one heat map per estimator, test placement by tracker noise.

Each cell's colour is the median of the estimator minus OLS in the test poses' mean position
error (um: below 0 the estimator is better; the sign of the report's tables and sentences),
on a scale symmetric about 0
shared by every estimator (the maps compare), logarithmic beyond LINEAR_UM (differences of a
tenth of a micrometre and of tens of micrometres both show); the cell's text gives the
difference and the fraction of draws in which the estimator beat OLS.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.colors import SymLogNorm

from scenarios.figures import plt, save_png
from scenarios.studies.liu_vs_ols.report import shown

CMAP = "RdBu_r"  # estimator minus OLS: red above 0 (worse than OLS), blue below (better)
LINEAR_UM = 0.1  # the colour scale is linear within +-LINEAR_UM, logarithmic beyond


def minus_ols_grid(summary: dict[str, Any], label: str) -> tuple[np.ndarray, np.ndarray]:
    """(median estimator minus OLS in um, better fraction), each (placements, sigmas)."""
    cells = summary["cells"]
    places, sigmas = summary["placements"], summary["sigmas_mm"]
    diff = np.full((len(places), len(sigmas)), np.nan)
    better = np.full_like(diff, np.nan)
    for i, p in enumerate(places):
        for j, s in enumerate(sigmas):
            e = cells[f"{p}/{s:g}"]["estimators"][label]
            diff[i, j] = e["minus_ols_um"]["median"]
            better[i, j] = e["better_fraction"]
    return diff, better


def heat_maps(out_dir: Path, summary: dict[str, Any]) -> dict[str, str]:
    grids = {label: minus_ols_grid(summary, label) for label in summary["estimators"]}
    vmax = max((float(np.nanmax(np.abs(g))) for g, _ in grids.values()), default=0.0)
    norm = SymLogNorm(LINEAR_UM, vmin=-max(vmax, LINEAR_UM), vmax=max(vmax, LINEAR_UM))
    places, sigmas = summary["placements"], summary["sigmas_mm"]
    written = {}
    for label, (diff, better) in grids.items():
        # about the shape of a view in the recording's 2 x 2 grid, so it fills it
        fig, ax = plt.subplots(figsize=(1.8 + 1.2 * len(sigmas), 1.9 + 0.9 * len(places)))
        im = ax.imshow(diff, cmap=CMAP, norm=norm, aspect="auto")
        for i in range(len(places)):
            for j in range(len(sigmas)):
                dark = abs(norm(diff[i, j]) - 0.5) > 0.3
                ax.text(
                    j,
                    i,
                    f"{diff[i, j]:+.2g} um\n{better[i, j]:.0%} better",
                    ha="center",
                    va="center",
                    fontsize=9,
                    color="white" if dark else "black",
                )
        ax.set_xticks(range(len(sigmas)), [f"{s:g}" for s in sigmas])
        ax.set_yticks(range(len(places)), places)
        ax.set_xlabel("tracker noise sigma (mm per coordinate)")
        ax.set_ylabel("test placement")
        ax.set_title(
            f"{shown(label)} minus OLS, median\n(test mean position error, um; "
            f"{summary['n_draws']} truth draws per cell)",
            fontsize=9,
        )
        bar = fig.colorbar(im, ax=ax, fraction=0.05, pad=0.03)
        bar.set_label("estimator - OLS (um; below 0: better)", fontsize=8)
        fig.tight_layout()
        name = f"regime_{label}"
        save_png(fig, out_dir / f"{name}.png")
        written[name] = f"{name}.png"
    return written
