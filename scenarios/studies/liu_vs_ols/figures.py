"""Error maps of the liu_vs_ols scenario (like Figs. 6-9): one PNG per quantity.

Rows are the three layers (upper, middle = test, lower), columns the stages (uncalibrated,
coarse, the fine estimators shown, the loop); the nodes of a layer form a grid, drawn as
image cells, x and y in mm. Two colour scales, each with its colour bar: the uncalibrated
column on its own (its 15 mm would leave every calibrated map uniformly dark), every other
stage on one shared scale from 0 to the largest of their errors, so that the stages compare
by colour; each panel's title states its max and mean.
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
        f"polisher: {qty} error of the head at every node ({unit}); uncalibrated on its own "
        "scale, every other stage on one shared scale (colour bars on the right)"
    )


BAR_TICKS = np.linspace(0.0, 1.0, 5)  # where a colour bar's labels sit, as a share of it


def _colour_bar(fig: plt.Figure, left: float, title: str) -> list[Any]:
    """A colour bar drawn once (a gradient from 0 to 1) with its title; returns the Text
    artists of its tick labels, which each quantity rewrites."""
    ax = fig.add_axes((left, 0.12, 0.012, 0.68))
    ax.imshow(
        np.linspace(0.0, 1.0, 256)[:, None],
        origin="lower",
        aspect="auto",
        cmap="viridis",
        extent=(0.0, 1.0, 0.0, 1.0),
    )
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=7, y=1.0)
    return [
        ax.text(1.4, t, "", fontsize=6, va="center", ha="left", transform=ax.transAxes)
        for t in BAR_TICKS
    ]


def write_figures(out_dir: Path, maps: dict[str, dict[str, Any]]) -> dict[str, str]:
    """maps[group][stage] = (poses (N, 6), PoseErrors); one PNG per quantity.

    The grid of panels is laid out and its axes (ticks, their labels, the axis names and the
    colour bars' gradients) drawn once for both quantities; each PNG draws only its images,
    titles, colour-bar labels and heading (and the frames, which lie over the images' edges)
    over them. Every layer spans the same x and y, so only the outer panels carry ticks (x on
    the bottom row, y on the left column): the inner ones have none at all, which spares
    drawing some two hundred ticks whose labels nobody would see."""
    n_rows, n_cols, panels = _panels(maps, "position")
    fig, axes = plt.subplots(
        n_rows, n_cols, figsize=(2.3 * n_cols + 1.0, 2.2 * n_rows + 0.6), squeeze=False, dpi=DPI
    )
    fig.subplots_adjust(left=0.05, right=0.855, bottom=0.08, top=0.86, wspace=0.3, hspace=0.55)
    images, extents = {}, {}
    for r, c, _, img, extent, _vmax in panels:
        ax = axes[r, c]
        images[r, c] = ax.imshow(img, origin="lower", extent=extent, cmap="viridis", vmin=0)
        extents[r, c] = extent
        ax.tick_params(labelsize=6)
        if r < n_rows - 1:
            ax.set_xticks([])
        else:
            ax.set_xlabel("x (mm)", fontsize=7)
        if c > 0:
            ax.set_yticks([])
        else:
            ax.set_ylabel("y (mm)", fontsize=7)
    bars = [_colour_bar(fig, 0.875, "uncalibrated"), _colour_bar(fig, 0.94, "others")]
    heading = fig.suptitle("", fontsize=9)
    changed = [heading, *bars[0], *bars[1]]
    for ax in axes.flat:
        changed += [*ax.images, *ax.spines.values(), ax.title]

    def frames() -> Iterator[Frame]:
        for qty in ("position", "orientation"):
            drawn = panels if qty == "position" else _panels(maps, qty)[2]
            top = [0.0, 0.0]  # the largest value of the uncalibrated column, of the others
            for _r, c, _, _, _, vmax in drawn:
                top[c > 0] = max(top[c > 0], vmax if np.isfinite(vmax) else 0.0)
            top = [t if t > 0 else 1e-12 for t in top]
            for r, c, title, img, extent, _vmax in drawn:
                if extent != extents[r, c]:  # the axes drawn once must fit every quantity
                    raise ValueError(
                        f"panel {r}, {c}: {qty} nodes span {extent}, not {extents[r, c]}"
                    )
                images[r, c].set_data(img)
                images[r, c].set_clim(0, top[c > 0])
                # y given: the title stays where it would be (ticks below), and the draw skips
                # placing it above every tick label of every panel
                axes[r, c].set_title(title, fontsize=7, y=1.0)
            unit = "mm" if qty == "position" else "deg"
            for labels, vmax in zip(bars, top, strict=True):
                for text, t in zip(labels, BAR_TICKS, strict=True):
                    text.set_text(f"{t * vmax:.3g} {unit}")
            heading.set_text(_suptitle(qty))
            yield out_dir / f"error_maps_{qty}.png", changed

    save_pngs(fig, frames())
    return {f"error_maps_{qty}": f"error_maps_{qty}.png" for qty in ("position", "orientation")}
