"""The charts and documents of a recording: error maps with their colour scales, estimates
as tables, metrics on the timeline, static figures, markdown texts, the loop's views."""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.recording.blueprints import Bounds, ErrorMap, Series
from scenarios.recording.parts import (
    colour_scale,
    error_colors,
    merge_nodes,
    node_spacing,
    parameter_table,
)
from scenarios.recording.session import _active, entity_part
from twin.mechanism import Mechanism

ERROR_MAP_SHARE = 0.3  # a node's radius as a share of the nodes' spacing: its colour seen
RELATIVE_IMAGE = re.compile(r"!\[([^\]]*)\]\((?![a-zA-Z][a-zA-Z0-9+.-]*:)([^)\s]+)\)")


def viewer_markdown(markdown: str) -> str:
    """``markdown`` with each image linked by a relative path (a report's figure beside it)
    replaced by its name and file, in italics: the viewer shows such a link as a broken
    image."""
    return RELATIVE_IMAGE.sub(r"*Figure: \1 (`\2`, beside the recording)*", markdown)


class ChartViews:
    """The charts and texts of a Recorder (a mixin of session.RecorderBase)."""

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
                radii=ERROR_MAP_SHARE * spacing,
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
            bounds.add(ticks + np.array([0.3 * float(np.max(bounds.hi - bounds.lo)), 0.0, 0.0]))
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
    def log_figure(self, name: str, png: bytes | str | Path, title: str) -> None:
        """A static figure (PNG bytes, or a PNG file such as a report's figure) in a 2D view
        titled ``title``: shown on any timeline, with the axes, names and log scales that a
        plot of rerun's cannot draw. ``figures.png_bytes`` turns a matplotlib figure into it."""
        data = Path(png).read_bytes() if isinstance(png, str | Path) else bytes(png)
        path = f"figures/{entity_part(name)}"
        image = self.rr.EncodedImage(contents=data, media_type="image/png")
        self._rec.log(path, image, static=True)
        self.logged.figures[path] = title

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
        """A figure of the report (a PNG written beside the recording): :meth:`log_figure`
        titled by its name."""
        self.log_figure(name, png, name.replace("_", " "))

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
    def log_causes(self, diag: Any, figure: Path | None, plots: list[Any], noise_mm: float) -> None:
        """The loop's cause: one figure per named effect against the variable that explains
        it (the diagnosis's own ``figure`` for the first), and the candidates held out."""
        from scenarios.recording.loop import log_causes

        log_causes(self, diag, figure, plots, noise_mm)

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
