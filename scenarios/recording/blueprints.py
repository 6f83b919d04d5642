"""The layout of a recording, built from what the study logged (see ``recording.Logged``).

One blueprint per recording, assembled when the recorder closes: the machine with the
targets and error arrows of each pose group (one 3D view per group), one labelled error-map
view per stage and layer, a report's figures (one 2D view each), one plot per family of
curves on the active timeline, bar charts, and text views (the verdict, the report's key
numbers, one parameter table per stage).
A view is made only for data that exists; a curve on another timeline than the active one
is not given a view (rerun plots against the active timeline only), nor is a pose group
posed on another pose timeline (``build_blueprint(log, timeline=...)`` opens on that one).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Bounds:
    """An axis-aligned box around logged positions (metres), grown point by point."""

    lo: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))
    hi: np.ndarray = field(default_factory=lambda: np.full(3, -np.inf))

    def add(self, points: np.ndarray) -> None:
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        p = p[np.all(np.isfinite(p), axis=1)]
        if len(p):
            self.lo = np.minimum(self.lo, p.min(axis=0))
            self.hi = np.maximum(self.hi, p.max(axis=0))

    @property
    def empty(self) -> bool:
        return not np.all(np.isfinite(self.lo))

    def eye(self, rr_blueprint: Any, direction=(1.0, -1.3, 0.8)) -> Any | None:
        """Camera looking at the box centre from far enough to see all of it."""
        if self.empty:
            return None
        centre = (self.lo + self.hi) / 2
        size = max(float(np.max(self.hi - self.lo)), 0.05)
        d = np.asarray(direction, dtype=float)
        position = centre + 1.5 * size * d / np.linalg.norm(d)
        return rr_blueprint.EyeControls3D(
            position=position.tolist(), look_target=centre.tolist(), eye_up=[0.0, 0.0, 1.0]
        )


@dataclass
class Series:
    """A curve under ``metrics/``: its timeline, its time points, drawn as points or lines."""

    timeline: str
    indices: set[int] = field(default_factory=set)
    points: bool = False

    @property
    def as_points(self) -> bool:
        return self.points or len(self.indices) < 2


@dataclass
class ErrorMap:
    stage: str
    layer: str
    vmax_mm: float
    bounds: Bounds


@dataclass
class Logged:
    """What a study logged, in the order it logged it: the blueprint is built from this."""

    mechanism: bool = False
    pose_timelines: dict[str, set[int]] = field(default_factory=dict)
    target_groups: dict[str, str] = field(default_factory=dict)  # path part -> name
    group_timelines: dict[str, str] = field(default_factory=dict)  # path part -> timeline
    machine_bounds: Bounds = field(default_factory=Bounds)
    error_maps: dict[str, ErrorMap] = field(default_factory=dict)  # entity path -> map
    series: dict[str, Series] = field(default_factory=dict)  # entity path -> curve
    bars: dict[str, str] = field(default_factory=dict)  # entity path -> view name
    texts: dict[str, str] = field(default_factory=dict)  # entity path -> view name
    images: dict[str, str] = field(default_factory=dict)  # entity path -> view name

    def active_timeline(self) -> str | None:
        """The timeline the viewer opens on: the one most curves are plotted against (a
        recording then shows every view filled), else the first pose timeline."""
        counts: dict[str, int] = {}
        for s in self.series.values():
            counts[s.timeline] = counts.get(s.timeline, 0) + 1
        if counts:
            return max(counts, key=lambda t: (counts[t], t in self.pose_timelines))
        return next(iter(self.pose_timelines), None)


TEXT_ORDER = ("verdict", "report")


def _family(path: str) -> str:
    """``metrics/lm_cost/fit`` -> ``metrics/lm_cost``; ``metrics/x`` -> ``metrics/x``."""
    parts = path.split("/")
    return "/".join(parts[:2])


def _row(rrb: Any, views: list[Any], name: str | None = None) -> Any:
    if len(views) == 1:
        return views[0]
    if len(views) <= 3:
        return rrb.Horizontal(*views, name=name)
    return rrb.Grid(*views, name=name)


def _stack(rrb: Any, parts: list[Any], shares: list[float]) -> Any | None:
    if not parts:
        return None
    if len(parts) == 1:
        return parts[0]
    return rrb.Vertical(*parts, row_shares=shares)


def machine_views(rrb: Any, log: Logged, active: str | None = None) -> list[Any]:
    if not (log.mechanism or log.target_groups):
        return []
    eye = log.machine_bounds.eye(rrb)
    groups: dict[str | None, str | None] = dict(log.target_groups) or {None: None}
    timeline = log.active_timeline() if active is None else active
    here = {g: n for g, n in groups.items() if log.group_timelines.get(g) == timeline}
    groups = here or groups  # groups posed on another timeline would be empty views
    views = []
    for g, label in groups.items():
        contents = ["world", "world/bodies/**"]
        name = "machine"
        if g is not None:
            contents.append(f"world/targets/{g}/**")
            name = f"{label}: machine, targets and error arrows"
        views.append(
            rrb.Spatial3DView(origin="world", contents=contents, name=name, eye_controls=eye)
        )
    return views


def error_map_views(rrb: Any, log: Logged) -> Any | None:
    by_layer: dict[str, list[Any]] = {}
    for path, em in log.error_maps.items():
        view = rrb.Spatial3DView(
            origin=path,
            contents=["$origin/**"],
            name=f"{em.stage} / {em.layer}, 0-{em.vmax_mm:.3g} mm: error map",
            eye_controls=em.bounds.eye(rrb, direction=(0.35, -0.6, 1.0)),
        )
        by_layer.setdefault(em.layer, []).append(view)
    rows = [_row(rrb, views, name=f"error maps: {layer}") for layer, views in by_layer.items()]
    if not rows:
        return None
    return rows[0] if len(rows) == 1 else rrb.Tabs(*rows)


def image_views(rrb: Any, log: Logged) -> Any | None:
    """A report's figures (heat maps ...), all at once: one 2D view each, in a grid."""
    views = [
        rrb.Spatial2DView(origin=p, contents=["$origin"], name=n) for p, n in log.images.items()
    ]
    if not views:
        return None
    return views[0] if len(views) == 1 else rrb.Grid(*views, name="figures")


def series_views(rrb: Any, log: Logged, timeline: str | None) -> list[Any]:
    families: dict[str, list[str]] = {}
    for path, s in log.series.items():
        if s.timeline == timeline:
            families.setdefault(_family(path), []).append(path)
    views = []
    for family, paths in families.items():
        label = family.split("/", 1)[-1].replace("_", " ")
        views.append(
            rrb.TimeSeriesView(
                origin=family,
                contents=[f"{p}" for p in paths],
                name=f"{label} against {timeline.replace('_', ' ')}",
                plot_legend=rrb.PlotLegend(visible=len(paths) > 1),
            )
        )
    views += [rrb.BarChartView(origin=p, name=n) for p, n in log.bars.items()]
    return views


def text_views(rrb: Any, log: Logged) -> Any | None:
    order = sorted(
        log.texts.items(),
        key=lambda kv: TEXT_ORDER.index(kv[0]) if kv[0] in TEXT_ORDER else len(TEXT_ORDER),
    )
    views = [rrb.TextDocumentView(origin=p, contents=["$origin"], name=n) for p, n in order]
    if not views:
        return None
    return views[0] if len(views) == 1 else rrb.Tabs(*views)


def build_blueprint(log: Logged, timeline: str | None = None) -> Any:
    """The blueprint of a recording; ``timeline`` overrides the one the viewer opens on."""
    import rerun.blueprint as rrb

    timeline = timeline or log.active_timeline()
    machine = machine_views(rrb, log, timeline)
    maps = error_map_views(rrb, log)
    left_parts, left_shares = [], []
    if machine:
        left_parts.append(_row(rrb, machine))
        left_shares.append(3.0)
    if maps is not None:
        left_parts.append(maps)
        left_shares.append(2.0)
    images = image_views(rrb, log)
    if images is not None:
        left_parts.append(images)
        left_shares.append(3.0)
    right_parts, right_shares = [], []
    for view in series_views(rrb, log, timeline):
        right_parts.append(view)
        right_shares.append(1.0)
    texts = text_views(rrb, log)
    if texts is not None:
        right_parts.append(texts)
        right_shares.append(1.5)
    left = _stack(rrb, left_parts, left_shares)
    right = _stack(rrb, right_parts, right_shares)
    columns = [c for c in (left, right) if c is not None]
    if not columns:
        root = rrb.Spatial3DView(origin="/", name="recording")
    elif len(columns) == 1:
        root = columns[0]
    else:
        root = rrb.Horizontal(*columns, column_shares=[3.0, 2.0])
    panels = [
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        # no timeline: nothing to scrub through (an empty TimePanel() was a chunk rerun
        # dropped with a warning, leaving the panel open)
        rrb.TimePanel(state="collapsed", timeline=timeline)
        if timeline
        else rrb.TimePanel(state="collapsed"),
    ]
    return rrb.Blueprint(root, *panels, auto_layout=False, auto_views=False)
