"""Error maps of the liu_vs_ols scenario (like Figs. 6-9): one PNG per quantity.

Rows are the three layers (upper, middle = test, lower), columns the stages (uncalibrated,
coarse, the fine estimators shown, the loop); the nodes of a layer form a grid, drawn as
image cells. Each panel has its own colour scale (the uncalibrated 15 mm would leave every
calibrated map uniformly dark), from 0 to its max, which its title states with the mean.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.figures import DPI, Frame, plt, save_pngs

SHOWN = ("uncalibrated", "coarse", "ols", "liu", "liu_paper_deg", "loop")


def _grid(xy: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, list[float]]:
    xs, ys = np.unique(np.round(xy[:, 0], 9)), np.unique(np.round(xy[:, 1], 9))
    img = np.full((len(ys), len(xs)), np.nan)
    ix = np.searchsorted(xs, np.round(xy[:, 0], 9))
    iy = np.searchsorted(ys, np.round(xy[:, 1], 9))
    img[iy, ix] = values
    dx = (xs[1] - xs[0]) / 2 if len(xs) > 1 else 1.0
    dy = (ys[1] - ys[0]) / 2 if len(ys) > 1 else 1.0
    return img, [xs[0] - dx, xs[-1] + dx, ys[0] - dy, ys[-1] + dy]


def _layers(maps: dict[str, dict[str, Any]]) -> list[tuple[str, float]]:
    out = []
    for group in ("calibration", "test"):
        if group in maps:
            poses = next(iter(maps[group].values()))[0]
            out += [(group, float(z)) for z in np.unique(np.round(poses[:, 2], 9))[::-1]]
    return sorted(out, key=lambda gz: -gz[1])


def _panels(maps: dict[str, dict[str, Any]], qty: str):
    """(row, column, title, image, extent, max) of every panel of one quantity."""
    rows = _layers(maps)
    stages = [s for s in SHOWN if all(s in maps[g] for g, _ in rows)]
    unit = "mm" if qty == "position" else "deg"
    out = []
    for r, (group, z) in enumerate(rows):
        for c, stage in enumerate(stages):
            poses, errs = maps[group][stage]
            sel = np.isclose(poses[:, 2], z)
            values = errs.position[sel] * 1e3 if qty == "position" else errs.orientation[sel]
            if qty != "position":
                values = np.degrees(values)
            img, extent = _grid(poses[sel, :2] * 1e3, values)
            title = (
                f"{stage}, z {z * 1e3:+.0f} mm ({group})\n"
                f"max {values.max():.3f}, mean {values.mean():.3f} {unit}"
            )
            out.append((r, c, title, img, extent, float(np.nanmax(img))))
    return len(rows), len(stages), out


def _suptitle(qty: str) -> str:
    unit = "mm" if qty == "position" else "deg"
    return (
        f"polisher: {qty} error of the head at every node ({unit}); each panel scaled from 0 "
        "(dark) to its own max (yellow)"
    )


def write_figures(out_dir: Path, maps: dict[str, dict[str, Any]]) -> dict[str, str]:
    """maps[group][stage] = (poses (N, 6), PoseErrors); one PNG per quantity.

    The grid of panels is laid out and its axes (ticks and their labels) drawn once for both
    quantities; each PNG draws only its images, titles and heading (and the frames, which lie
    over the images' edges) over them. Every layer spans the same x and y, so only the outer
    panels carry ticks (x on the bottom row, y on the left column): the inner ones have none at
    all, which spares drawing some two hundred ticks whose labels nobody would see."""
    n_rows, n_cols, panels = _panels(maps, "position")
    fig, axes = plt.subplots(
        n_rows, n_cols, figsize=(2.3 * n_cols, 2.2 * n_rows + 0.4), squeeze=False, dpi=DPI
    )
    fig.subplots_adjust(left=0.04, right=0.99, bottom=0.05, top=0.88, wspace=0.3, hspace=0.55)
    images, extents = {}, {}
    for r, c, _, img, extent, _vmax in panels:
        ax = axes[r, c]
        images[r, c] = ax.imshow(img, origin="lower", extent=extent, cmap="viridis", vmin=0)
        extents[r, c] = extent
        ax.tick_params(labelsize=6)
        if r < n_rows - 1:
            ax.set_xticks([])
        if c > 0:
            ax.set_yticks([])
    heading = fig.suptitle("", fontsize=9)
    changed = [heading]
    for ax in axes.flat:
        changed += [*ax.images, *ax.spines.values(), ax.title]

    def frames() -> Iterator[Frame]:
        for qty in ("position", "orientation"):
            drawn = panels if qty == "position" else _panels(maps, qty)[2]
            for r, c, title, img, extent, vmax in drawn:
                if extent != extents[r, c]:  # the axes drawn once must fit every quantity
                    raise ValueError(
                        f"panel {r}, {c}: {qty} nodes span {extent}, not {extents[r, c]}"
                    )
                images[r, c].set_data(img)
                images[r, c].set_clim(0, vmax)
                # y given: the title stays where it would be (ticks below), and the draw skips
                # placing it above every tick label of every panel
                axes[r, c].set_title(title, fontsize=7, y=1.0)
            heading.set_text(_suptitle(qty))
            yield out_dir / f"error_maps_{qty}.png", changed

    save_pngs(fig, frames())
    return {f"error_maps_{qty}": f"error_maps_{qty}.png" for qty in ("position", "orientation")}
