"""Charts and text in a recording: error maps with their colour scale, metrics, bars, the
estimates and the report as text views, figures, and the loop's residuals and verdict."""

from __future__ import annotations

import functools
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.recording.blueprints import Bounds, ErrorMap, Series
from scenarios.recording.session import _active, entity_part
from twin.mechanism import Mechanism

ERROR_MAP_RADIUS = 0.004  # metres


@functools.cache
def _viridis() -> Any:
    """The viridis colour map, looked up once (each lookup copies it and builds its table)."""
    from matplotlib import colormaps

    return colormaps["viridis"]


def error_colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """RGB (N, 3) uint8 from viridis over [0, vmax]; NaN values come out grey."""
    v = np.asarray(values, dtype=float)
    rgb = _viridis()(np.clip(np.nan_to_num(v) / max(vmax, 1e-300), 0.0, 1.0))[:, :3]
    rgb[~np.isfinite(v)] = 0.5
    return np.round(rgb * 255).astype(np.uint8)


RELATIVE_IMAGE = re.compile(r"!\[([^\]]*)\]\((?![a-zA-Z][a-zA-Z0-9+.-]*:)([^)\s]+)\)")


def viewer_markdown(markdown: str) -> str:
    """``markdown`` with each image linked by a relative path (a report's figure beside it)
    replaced by its name and file, in italics: the viewer shows such a link as a broken
    image."""
    return RELATIVE_IMAGE.sub(r"*Figure: \1 (`\2`, beside the recording)*", markdown)


def merge_nodes(positions: np.ndarray, errors: np.ndarray) -> tuple[np.ndarray, ...]:
    """Unique positions (to 0.1 um), the largest error at each, and how many shared it."""
    positions = np.asarray(positions, dtype=float).reshape(-1, 3)
    if len(positions) != len(errors):
        return positions, errors, np.ones(len(positions), dtype=int)
    keys = np.round(positions * 1e7).astype(np.int64)
    _, first, inverse, counts = np.unique(
        keys, axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    inverse = inverse.ravel()
    worst = np.full(len(first), -np.inf)
    np.maximum.at(worst, inverse, np.where(np.isfinite(errors), errors, -np.inf))
    worst[~np.isfinite(worst)] = np.nan
    order = np.argsort(first)  # keep the logged order of first appearance
    return positions[first[order]], worst[order], counts[order]


def node_spacing(nodes: np.ndarray) -> float:
    """The smallest distance between two nodes (metres); 1 cm for fewer than two."""
    if len(nodes) < 2:
        return 0.01
    d = np.linalg.norm(nodes[:, None, :] - nodes[None, :, :], axis=-1)
    d[np.diag_indices(len(nodes))] = np.inf
    return float(max(d.min(), 1e-4))


def colour_scale(
    bounds: Bounds, spacing: float, vmax: float, n: int = 10
) -> tuple[np.ndarray, list[float], np.ndarray, list[str]]:
    """A vertical column of ``n`` boxes beside the nodes (viridis, 0 at the bottom) and two
    labelled ticks, 0 and vmax in mm (a middle label overlaps them in a small view)."""
    size = bounds.hi - bounds.lo
    height = max(float(size.max()), 4 * spacing)
    x = bounds.hi[0] + 1.5 * spacing
    y = (bounds.lo[1] + bounds.hi[1]) / 2
    z0 = (bounds.lo[2] + bounds.hi[2]) / 2 - height / 2
    step = height / n
    centres = np.array([[x, y, z0 + (k + 0.5) * step] for k in range(n)])
    half = [0.25 * spacing, 0.25 * spacing, step / 2]
    ticks = np.array([[x + 0.4 * spacing, y, z0 + f * height] for f in (0.0, 1.0)])
    return centres, half, ticks, [f"{f * vmax:.3g} mm" for f in (0.0, 1.0)]


def parameter_table(
    stage: str,
    names: Sequence[str],
    estimates: np.ndarray,
    std: np.ndarray | None,
    truth: np.ndarray | None,
    unit: str,
) -> str:
    est = np.asarray(estimates, dtype=float)
    head = ["parameter", f"estimate ({unit})", "std"]
    if truth is not None:
        head += ["truth", "estimate - truth", "|dev| / std"]
    rows = [f"### {stage}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for k, name in enumerate(names):
        s = float("nan") if std is None else float(std[k])
        cells = [name, f"{est[k]:.4g}", "" if std is None else f"{s:.4g}"]
        if truth is not None:
            dev = est[k] - float(truth[k])
            z = abs(dev) / s if np.isfinite(s) and s > 0 else float("nan")
            cells += [f"{float(truth[k]):.4g}", f"{dev:+.3g}", f"{z:.2g}"]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


class ChartViews:
    """Error maps, metrics, bars, text, images and the loop (a mixin of Recorder)."""

    @_active
    def log_error_map(
        self,
        stage: str,
        layer: str,
        positions: np.ndarray,
        errors_mm: np.ndarray,
        vmax_mm: float | None = None,
    ) -> None:
        """Nodes (N, 3, metres) coloured by error (viridis over [0, vmax_mm]), static, with a
        colour scale in mm beside them. Nodes at one position (several orientations) show the
        largest error there; spheres are sized to the node spacing."""
        rr = self.rr
        positions = np.asarray(positions, dtype=float)
        errors = np.asarray(errors_mm, dtype=float).ravel()
        finite = errors[np.isfinite(errors)]
        vmax = float(vmax_mm) if vmax_mm is not None else float(finite.max(initial=0.0))
        if positions.ndim != 2 or positions.shape[1] != 3:  # rerun names the mistake
            self._rec.log("error_maps/invalid", rr.Points3D(positions), static=True)
            return
        nodes, worst, repeats = merge_nodes(positions, errors)
        root = f"error_maps/{entity_part(stage)}/{entity_part(layer)}"
        spacing = node_spacing(nodes)
        many = "max over " if np.any(repeats > 1) else ""
        labels = [f"{many}{e:.3f} mm" for e in worst]
        self._rec.log("error_maps", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._rec.log(
            f"{root}/nodes",
            rr.Points3D(
                nodes,
                colors=error_colors(worst, vmax),
                radii=min(ERROR_MAP_RADIUS, 0.3 * spacing),
                labels=labels,
                show_labels=False,
            ),
            static=True,
        )
        bounds = Bounds()
        bounds.add(nodes)
        if not bounds.empty:
            centres, half, ticks, tick_labels = colour_scale(bounds, spacing, vmax)
            self._rec.log(
                f"{root}/scale_mm",
                rr.Boxes3D(
                    centers=centres,
                    half_sizes=half,
                    colors=error_colors(np.linspace(0, vmax, len(centres)), vmax),
                    fill_mode="solid",
                ),
                static=True,
            )
            self._rec.log(
                f"{root}/scale_mm/ticks",
                rr.Points3D(ticks, radii=1e-4, labels=tick_labels, show_labels=True),
                static=True,
            )
            bounds.add(centres)
        self.logged.error_maps[root] = ErrorMap(stage, layer, vmax, bounds)

    @_active
    def log_parameters(
        self,
        stage: str,
        names: Sequence[str],
        estimates: np.ndarray,
        std: np.ndarray | None = None,
        truth: np.ndarray | None = None,
        unit: str = "mm or deg",
    ) -> None:
        """A markdown table of estimates by name, with standard errors and, when the truth is
        known, the deviation from it in standard errors (one table view per stage)."""
        self.log_text(
            f"parameters/{stage}",
            parameter_table(stage, names, estimates, std, truth, unit),
            name=f"parameters: {stage}",
        )

    @_active
    def log_metric(self, name: str, timeline: str, index: int, value: float) -> None:
        """One point of the curve ``metrics/<name>`` against ``timeline``."""
        self._scalar(name, timeline, index, value, points=False)

    @_active
    def log_points(self, name: str, timeline: str, index: int, value: float) -> None:
        """One point of ``metrics/<name>`` against ``timeline``, drawn as a marker (a scatter
        of a per-pose value against the variable the timeline is)."""
        self._scalar(name, timeline, index, value, points=True)

    def _scalar(self, name: str, timeline: str, index: int, value: float, points: bool) -> None:
        path = f"metrics/{name}"
        self._time(timeline, index)
        self._rec.log(path, self.rr.Scalars(float(value)))
        s = self.logged.series.setdefault(path, Series(timeline, points=points))
        if s.timeline != timeline:
            raise ValueError(f"{path}: logged against {s.timeline} and {timeline}")
        s.indices.add(int(index))

    @_active
    def log_bars(self, name: str, labels: Sequence[str], values: np.ndarray, unit: str) -> None:
        """A static bar chart ``bars/<name>``; the view's name lists the bars in order."""
        values = np.nan_to_num(np.asarray(values, dtype=float))
        self._rec.log(f"bars/{name}", self.rr.BarChart(values), static=True)
        self.logged.bars[f"bars/{name}"] = f"{name.replace('_', ' ')} ({unit}): " + ", ".join(
            labels
        )

    @_active
    def log_text(self, path: str, markdown: str, name: str | None = None) -> None:
        """A static markdown document (a table, a residual diagnosis ...), one text view.
        A figure a report links by a relative path is named instead (:func:`viewer_markdown`):
        the viewer cannot open files beside the recording."""
        doc = self.rr.TextDocument(viewer_markdown(markdown), media_type=self.rr.MediaType.MARKDOWN)
        self._rec.log(path, doc, static=True)
        self.logged.texts[path] = name or path.replace("_", " ")

    @_active
    def log_image(self, name: str, png: Path) -> None:
        """A figure of the report (a PNG written beside the recording) as a static image,
        ``figures/<name>``, in a 2D view of its own."""
        path = f"figures/{entity_part(name)}"
        self._rec.log(path, self.rr.EncodedImage(path=Path(png)), static=True)
        self.logged.images[path] = name.replace("_", " ")

    @_active
    def log_loop(
        self,
        mech: Mechanism,
        order: np.ndarray,
        prediction: Any,
        measured: np.ndarray,
        after: np.ndarray,
    ) -> None:
        """Loop closing: each pose's residual before (``prediction``, a geometric fit's) and
        after the named effect (``after`` targets), as arrows and against measurement order."""
        from scenarios.recording.loop import log_loop

        log_loop(self, mech, order, prediction, measured, after)

    @_active
    def log_verdict(
        self, diagnosis: Any, before_mm: float, after_mm: float, noise_mm: float
    ) -> None:
        """The named effect, why, and the residual before and after, as the verdict view."""
        from scenarios.recording.loop import verdict_markdown

        self.log_text(
            "verdict", verdict_markdown(diagnosis, before_mm, after_mm, noise_mm), "verdict"
        )

    @_active
    def log_report(self, study: str, summary: dict[str, Any]) -> None:
        """The study's report.md (its key numbers and tables) as the ``report`` text view."""
        import importlib

        from scenarios.studies import STUDIES

        report = importlib.import_module(STUDIES[study][1]).report
        self.log_text("report", report(summary), name="report: key numbers")
