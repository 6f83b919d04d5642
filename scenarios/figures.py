"""PNG figures for reports (matplotlib, Agg), each written atomically.

Every function takes the output path and a title first, writes the PNG through a temporary
file in the same folder (``os.replace``), so a failed write never leaves a partial figure
behind nor destroys an older one, and returns the path written. Figures that differ only in
some of their artists (the same parameters' estimates by two methods, the same panels of two
quantities) are drawn by :func:`save_pngs`, what they share drawn once
(:func:`parameter_bars_pngs` takes the names first, then one :class:`Bars` per chart).
"""

from __future__ import annotations

import contextlib
import gc
import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.image
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.colors import Normalize

from common.atomic_files import write_with_atomic

DPI = 110
PNG_OPTIONS = {"compress_level": 3}  # zlib's default, 6, takes twice the time for a few % less
CMAP = "viridis"

Panel = tuple[str, np.ndarray, np.ndarray]  # (name, xy_mm (N, 2), errors (N,))
Frame = tuple[Path, Sequence[Artist]]  # (path, the artists this frame changed)


@contextlib.contextmanager
def collection_paused() -> Iterator[None]:
    """No automatic garbage collection inside (the state before is restored after).

    Drawing figures makes some hundred thousand objects that live in reference cycles until
    the figure is closed; collected as they are made, they were promoted to the oldest
    generation and set off full collections of the whole process (0.2 s in liu_vs_ols, every
    other run). Paused, they are collected at once, young, by the first collection after."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def save_png(fig: plt.Figure, path: Path, close: bool = True) -> Path:
    """Write ``fig`` to ``path`` atomically (a temporary sibling, then a rename), then close it
    (``close=False``: keep it open, to be drawn again with other data)."""
    try:
        return write_with_atomic(
            path,
            lambda tmp: fig.savefig(tmp, dpi=DPI, format="png", pil_kwargs=PNG_OPTIONS),
            suffix=".png.tmp",
        )
    finally:
        if close:
            plt.close(fig)


def png_bytes(fig: plt.Figure, close: bool = True) -> bytes:
    """``fig`` as PNG bytes (at DPI, as save_png), for a recording; then closed."""
    import io

    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, dpi=DPI, format="png", pil_kwargs=PNG_OPTIONS)
    finally:
        if close:
            plt.close(fig)
    return buffer.getvalue()


def save_pngs(fig: plt.Figure, frames: Iterable[Frame], close: bool = True) -> list[Path]:
    """One PNG per frame of ``fig``, what the frames share drawn once (at DPI, as save_png).

    ``frames`` yields (path, changed) after setting the figure as that frame is to look;
    ``changed`` are the artists that differ between frames. Every other artist is drawn once,
    at the first frame, as a background; each frame starts from a copy of it and draws its
    changed artists over it, in the order a full draw takes them (each parent's patch first,
    then its children by z-order, axes recursed into). The picture is that of a full draw as
    long as the changed artists move none of the others (limits, aspect and layout stay) and
    none of the others is drawn over a changed one (keep spines among the changed artists of
    an axes whose image or data reach its edges). The figure is left at DPI."""
    written: list[Path] = []
    background = None
    animated: list[Artist] = []
    try:
        for path, changed in frames:
            for artist in changed:
                artist.set_animated(True)  # left out of the background's draw
            animated += changed
            canvas = fig.canvas
            if background is None:
                fig.set_dpi(DPI)
                canvas.draw()
                background = canvas.copy_from_bbox(fig.bbox)
            else:
                canvas.restore_region(background)
            renderer = canvas.get_renderer()
            wanted = {id(a) for a in changed}
            for artist in _in_draw_order(fig):
                if id(artist) in wanted:
                    artist.draw(renderer)
            written.append(_write_canvas(fig, path))
    finally:
        for artist in animated:  # a figure's draw, even savefig's, leaves animated ones out
            artist.set_animated(False)
        if close:
            plt.close(fig)
    return written


def _write_canvas(fig: plt.Figure, path: Path) -> Path:
    """What the canvas of ``fig`` holds as a PNG, written atomically as savefig writes it."""
    pixels = fig.canvas.buffer_rgba()
    return write_with_atomic(
        path,
        lambda tmp: matplotlib.image.imsave(
            tmp, pixels, format="png", origin="upper", dpi=fig.dpi, pil_kwargs=PNG_OPTIONS
        ),
        suffix=".png.tmp",
    )


def _in_draw_order(parent: plt.Figure | Axes) -> Iterator[Artist]:
    """The artists of a figure or an axes in the order its draw takes them: its patch, then
    its other children sorted by z-order (a stable sort), the artists of an axes in its
    place."""
    yield parent.patch
    children = [a for a in parent.get_children() if a is not parent.patch]
    for artist in sorted(children, key=lambda a: a.get_zorder()):
        if isinstance(artist, Axes):
            if artist.get_visible():
                yield from _in_draw_order(artist)
        else:
            yield artist


def _finite_max(values: np.ndarray) -> float:
    """The largest finite value, at least a tiny positive number (a usable colour scale)."""
    v = np.asarray(values, dtype=float)
    return max(float(np.max(v[np.isfinite(v)], initial=0.0)), 1e-12)


def _draw_map(ax: plt.Axes, xy: np.ndarray, errors: np.ndarray, norm: Normalize, unit: str):
    """Colour the nodes of one layer (filled contours under the nodes when they span an
    area), ring and annotate the largest error; NaN nodes are grey crosses."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    e = np.asarray(errors, dtype=float).ravel()
    if xy.shape[0] != e.shape[0]:
        raise ValueError(f"{xy.shape[0]} node positions but {e.shape[0]} error values")
    ok = np.isfinite(e)
    pts = xy[ok]
    spans_area = len(np.unique(pts, axis=0)) >= 4 and (
        np.linalg.matrix_rank(pts - pts.mean(axis=0), tol=1e-9 * np.ptp(pts).clip(1e-12)) == 2
    )
    if spans_area and np.ptp(e[ok]) > 0:
        levels = np.linspace(norm.vmin, norm.vmax, 15)
        ax.tricontourf(*pts.T, e[ok], levels=levels, cmap=CMAP, norm=norm, extend="max", alpha=0.85)
    size = float(np.clip(4000.0 / max(len(e), 1), 12.0, 140.0))
    sc = ax.scatter(
        pts[:, 0], pts[:, 1], c=e[ok], cmap=CMAP, norm=norm, s=size, edgecolors="k", lw=0.4
    )
    if not ok.all():
        ax.scatter(xy[~ok, 0], xy[~ok, 1], marker="x", color="0.5", s=size, label="no value")
        ax.legend(fontsize=7, loc="best")
    if ok.any():  # ring the largest error; its label points into the map, not off it
        k = int(np.flatnonzero(ok)[np.argmax(e[ok])])
        right, up = xy[k] > np.median(pts, axis=0)
        ax.scatter(*xy[k], s=size * 2.5, facecolors="none", edgecolors="red", lw=1.4)
        ax.annotate(
            f"max {e[k]:.4g} {unit}".strip(),
            xy[k],
            xytext=(-9 if right else 9, -9 if up else 9),
            textcoords="offset points",
            ha="right" if right else "left",
            va="top" if up else "bottom",
            fontsize=8,
            color="red",
            bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "none", "alpha": 0.85},
        )
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.08 * max(float(np.max(hi - lo)), 1e-9)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)  # contours stick to the data: leave room for nodes
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.grid(alpha=0.25)
    return sc


def _unit(label: str) -> str:
    """'position error (mm)' -> 'mm' (empty if the label carries no unit in brackets)."""
    return label[label.rfind("(") + 1 : label.rfind(")")] if label.endswith(")") else ""


def error_map_png(
    path: Path,
    title: str,
    xy_mm: np.ndarray,
    errors: np.ndarray,
    label: str,
    vmax: float | None = None,
) -> Path:
    """An error over the nodes of one layer: x, y of the nodes, colour = error (``label``
    names the quantity and its unit, e.g. 'position error (mm)'), the maximum annotated."""
    norm = Normalize(0.0, _finite_max(errors) if vmax is None else vmax)
    fig, ax = plt.subplots(figsize=(6.0, 5.0), constrained_layout=True)
    sc = _draw_map(ax, xy_mm, errors, norm, _unit(label))
    fig.colorbar(sc, ax=ax, label=label, shrink=0.9)
    ax.set_title(title, fontsize=10)
    return save_png(fig, path)


def error_maps_png(
    path: Path,
    title: str,
    panels: Sequence[Panel],
    label: str,
    shared_scale: bool = True,
) -> Path:
    """Several layers or stages side by side (up to 4 a row); ``shared_scale`` puts them on
    one colour scale from 0 to the largest error of all panels (before/after comparisons)."""
    if not panels:
        raise ValueError("error_maps_png needs at least one panel")
    n = len(panels)
    cols = min(n, 4)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(3.6 * cols + 1.3, 3.4 * rows + 0.6), squeeze=False
    )
    fig.set_layout_engine("constrained")
    vmax = max(_finite_max(e) for _, _, e in panels)
    for ax, (name, xy, errors) in zip(axes.flat, panels, strict=False):
        norm = Normalize(0.0, vmax if shared_scale else _finite_max(errors))
        sc = _draw_map(ax, xy, errors, norm, _unit(label))
        ax.set_title(name, fontsize=9)
        if not shared_scale:
            fig.colorbar(sc, ax=ax, label=label, shrink=0.85)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    if shared_scale:
        fig.colorbar(sc, ax=axes.ravel().tolist(), label=label, shrink=0.85)
    fig.suptitle(title, fontsize=10)
    return save_png(fig, path)


class Bars(NamedTuple):
    """One chart of :func:`parameter_bars_pngs`: where, its title, the estimates and, if
    known, their standard errors and the truth (each (n,), in the order of the names)."""

    path: Path
    title: str
    estimates: np.ndarray
    std: np.ndarray | None = None
    truth: np.ndarray | None = None


def parameter_bars_png(
    path: Path,
    title: str,
    names: Sequence[str],
    estimates: np.ndarray,
    std: np.ndarray | None = None,
    truth: np.ndarray | None = None,
    unit_label: str = "mm / deg",
) -> Path:
    """Horizontal bars of estimates with ±2 std error bars and truth markers; the figure
    grows with the number of parameters so that 54+ names stay readable."""
    return parameter_bars_pngs(names, [Bars(path, title, estimates, std, truth)], unit_label)[0]


def parameter_bars_pngs(
    names: Sequence[str], charts: Sequence[Bars], unit_label: str = "mm / deg"
) -> list[Path]:
    """:func:`parameter_bars_png` of several estimates of the same parameters, one PNG each:
    the names' column (most of the drawing) is laid out and drawn once for all."""
    n = len(names)
    charts = [c._replace(estimates=np.asarray(c.estimates, dtype=float)) for c in charts]
    for c in charts:
        if c.estimates.shape != (n,):
            raise ValueError(f"{n} parameter names but estimates of shape {c.estimates.shape}")
    if not charts:
        return []
    fontsize = 7 if n <= 60 else 6
    width, height = 7.5, 1.4 + 0.19 * n
    fig, ax = plt.subplots(figsize=(width, height), dpi=DPI)
    # fixed margins (inches) instead of a layout engine, which draws the figure once more:
    # the names' column from their longest (about 0.6 em a character), title and x label
    name_in = 0.25 + 0.6 * fontsize / 72 * max((len(str(v)) for v in names), default=1)
    fig.subplots_adjust(
        left=name_in / width, right=1 - 0.15 / width, top=1 - 0.35 / height, bottom=0.55 / height
    )
    y = np.arange(n)
    ax.set_yticks(y, names, fontsize=fontsize)
    ax.set_ylim(n - 0.5, -0.5)
    ax.grid(axis="x", alpha=0.3)
    ax.set_xlabel(unit_label)

    def frames() -> Iterator[Frame]:
        drawn: list = []
        drawn_before = False
        for c in charts:
            for old in drawn:  # the previous chart's bars, error bars, markers and zero line
                old.remove()
            err = None if c.std is None else 2.0 * np.nan_to_num(np.asarray(c.std, dtype=float))
            label = "estimate" if c.std is None else "estimate ± 2 std"
            ax.barh(
                y, c.estimates, xerr=err, color="#4c78a8", ecolor="#333333", capsize=2, label=label
            )
            drawn = list(ax.containers)  # the bars' and the error bars'
            if c.truth is not None:
                drawn += ax.plot(c.truth, y, "D", color="#e45756", markersize=3.5, label="truth")
            drawn.append(ax.axvline(0.0, color="#999999", linewidth=0.6))
            if drawn_before:  # the x limits of this chart alone (the first: the fresh axes')
                ax.relim()
                ax.autoscale_view()
            drawn_before = True
            # y given: where the title would be placed anyway (no tick labels on top), without
            # measuring every name for it
            ax.set_title(c.title, fontsize=10, y=1.0)
            ax.legend(fontsize=7, loc="best")
            # all but the names' column (and the axes' background) changes from chart to chart
            yield c.path, [a for a in ax.get_children() if a not in (ax.patch, ax.yaxis)]

    return save_pngs(fig, frames())


def index_vs_count_png(
    path: Path,
    title: str,
    counts: Sequence[int],
    series: Mapping[str, Sequence[float]],
    ylabel: str,
    log_y: bool = True,
    stop: int | None = None,
) -> Path:
    """An observability index against the number of poses, one line per method (a series
    shorter than ``counts`` covers its first counts); ``stop``: the count where the first
    series stops improving, marked and its plateau shaded."""
    fig, ax = plt.subplots(figsize=(6.5, 4.0), constrained_layout=True)
    for label, values in series.items():
        ax.plot(list(counts)[: len(values)], values, marker=".", label=label)
    if stop is not None and len(counts):
        ax.axvline(stop, color="k", lw=0.9, ls="--")
        ax.axvspan(stop, max(counts), color="0.85", alpha=0.5, lw=0)
        ax.annotate(
            f"stops improving at {stop} poses",
            (stop, 0.95),
            xycoords=("data", "axes fraction"),
            xytext=(4, 0),
            textcoords="offset points",
            fontsize=8,
            va="top",
        )
    if log_y:
        ax.set_yscale("log")
    ax.set_xlabel("number of poses")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    return save_png(fig, path)


def _stats_label(label: str, v: np.ndarray) -> str:
    if v.size == 0:
        return f"{label}: no finite value"
    std = float(np.std(v, ddof=1)) if v.size > 1 else 0.0
    return f"{label}: n {v.size}, mean {np.mean(v):.4g}, std {std:.3g}"


def histogram_png(
    path: Path,
    title: str,
    values_by_label: Mapping[str, np.ndarray],
    xlabel: str,
    bins: int = 50,
) -> Path:
    """Overlaid histograms on common bins (e.g. Monte Carlo distributions of an estimate),
    each labelled with its mean and standard deviation."""
    data = {k: np.asarray(v, dtype=float).ravel() for k, v in values_by_label.items()}
    data = {k: v[np.isfinite(v)] for k, v in data.items()}
    everything = np.concatenate([v for v in data.values()] + [np.zeros(0)])
    if everything.size == 0:
        raise ValueError("histogram_png has no finite values to draw")
    edges = np.histogram_bin_edges(everything, bins=bins)
    fig, ax = plt.subplots(figsize=(6.5, 4.0), constrained_layout=True)
    for label, v in data.items():
        ax.hist(
            v,
            bins=edges,
            alpha=0.5,
            histtype="stepfilled",
            edgecolor="k",
            lw=0.4,
            label=_stats_label(label, v),
        )
    ax.set_xlabel(xlabel)
    ax.set_ylabel("count")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return save_png(fig, path)
