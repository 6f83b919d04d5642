"""The regime map's figures: one heat map per estimator, tracker noise by test placement.

Each cell's colour is the median of the estimator minus OLS in the test poses' mean position
error (mm: below 0 the estimator is better; the sign of the report's tables and sentences),
on a scale symmetric about 0 shared by every estimator (the maps compare), logarithmic beyond
LINEAR_MM (differences of a tenth of a micrometre and of tens of micrometres both show); the
cell's text gives the difference and the fraction of draws in which the estimator beat OLS.
A map stands upright (noise down, placements across, the colour scale below), about the
shape of one of the four views side by side in the recording, with text of 10-11 points.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.colors import SymLogNorm

from scenarios.figures import plt, save_png
from scenarios.studies.liu_vs_ols.report import shown

CMAP = "RdBu_r"  # estimator minus OLS: red above 0 (worse than OLS), blue below (better)
LINEAR_MM = 1e-4  # the colour scale is linear within +-LINEAR_MM, logarithmic beyond


def minus_ols_grid(summary: dict[str, Any], label: str) -> tuple[np.ndarray, np.ndarray]:
    """(median estimator minus OLS in mm, better fraction), each (sigmas, placements)."""
    cells = summary["cells"]
    places, sigmas = summary["placements"], summary["sigmas_mm"]
    diff = np.full((len(sigmas), len(places)), np.nan)
    better = np.full_like(diff, np.nan)
    for i, s in enumerate(sigmas):
        for j, p in enumerate(places):
            e = cells[f"{p}/{s:g}"]["estimators"][label]
            diff[i, j] = e["minus_ols_um"]["median"] * 1e-3
            better[i, j] = e["better_fraction"]
    return diff, better


def cell_text(diff_mm: float, better: float) -> str:
    """A cell's two lines: the difference in mm (to 0.1 um) and the share of draws better."""
    return f"{diff_mm:+.4f}\n{better:.0%} better"


def heat_maps(out_dir: Path, summary: dict[str, Any]) -> dict[str, str]:
    grids = {label: minus_ols_grid(summary, label) for label in summary["estimators"]}
    vmax = max((float(np.nanmax(np.abs(g))) for g, _ in grids.values()), default=0.0)
    top = max(vmax, LINEAR_MM)
    norm = SymLogNorm(LINEAR_MM, vmin=-top, vmax=top)
    places, sigmas = summary["placements"], summary["sigmas_mm"]
    written = {}
    for label, (diff, better) in grids.items():
        fig, ax = plt.subplots(
            figsize=(1.1 + 1.0 * len(places), 2.3 + 0.62 * len(sigmas)), layout="constrained"
        )
        im = ax.imshow(diff, cmap=CMAP, norm=norm, aspect="auto")
        for i in range(len(sigmas)):
            for j in range(len(places)):
                dark = abs(norm(diff[i, j]) - 0.5) > 0.3
                ax.text(
                    j,
                    i,
                    cell_text(diff[i, j], better[i, j]),
                    ha="center",
                    va="center",
                    fontsize=10,
                    color="white" if dark else "black",
                )
        ax.set_xticks(range(len(places)), places, fontsize=10)
        ax.set_yticks(range(len(sigmas)), [f"{s:g}" for s in sigmas], fontsize=10)
        ax.set_xlabel("test placement", fontsize=10)
        ax.set_ylabel("tracker noise sigma (mm)", fontsize=10)
        ax.set_title(
            f"{shown(label)} minus OLS\nmedian of {summary['n_draws']} draws, test mean (mm)",
            fontsize=11,
        )
        ticks = [t for t in (-1e-2, -1e-3, 0.0, 1e-3, 1e-2) if abs(t) <= top]
        bar = fig.colorbar(im, ax=ax, orientation="horizontal", fraction=0.06, pad=0.02)
        bar.set_ticks(ticks, labels=[f"{t:g}" for t in ticks], fontsize=9)
        bar.set_label("estimator - OLS (mm; below 0: better)", fontsize=10)
        name = f"regime_{label}"
        save_png(fig, out_dir / f"{name}.png")
        written[name] = f"{name}.png"
    return written
