"""The layout of a recording, built from what the study logged (see ``recording.Logged``).

One blueprint per recording, assembled when the recorder closes. A recording has at most one
timeline (the poses'), so the layout has one face: every view holds data on it. Curves against
anything else (an iteration, a rank index, a pose count, a variable that explains an effect)
are static figures (``Recorder.log_figure``), shown on any timeline. The views: the machine
with the targets and error arrows of each pose group (one 3D view per group, the camera on
its targets), one labelled error-map view per stage and layer, the figures, one plot per
family of curves on the timeline, bar charts, and text views (the verdict, the report's key
numbers, one parameter table per stage). A view is made only for data that exists.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

FIT_MARGIN = 1.1  # a machine view's eye this much farther than the tightest fit: a rim
FOV_Y_DEG = 55.0  # the viewer's vertical field of view in a 3D view (its default)
EYE_DIRECTION = (1.0, -1.3, 1.0)  # from a view's centre to its eye: from the front, above
EYE_ABOVE, FLAT_SHARE = (1.0, -1.3, 2.6), 0.25  # a flat layer of targets: from higher up
WINDOW, TITLE_BAR = (1600, 940), 25  # pixels: a viewer window's views (the layout's whole) and
# a view's title bar; the machine views' cameras are framed for views of that share of it
CORNERS = [(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)]


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

    def eye(self, rr_blueprint: Any, direction=(1.0, -1.3, 0.8), distance: float = 1.5) -> Any:
        """Camera looking at the box centre from ``distance`` times its size (None: empty)."""
        if self.empty:
            return None
        centre = (self.lo + self.hi) / 2
        d = np.asarray(direction, dtype=float)
        position = centre + distance * self.size * d / np.linalg.norm(d)
        return rr_blueprint.EyeControls3D(
            position=position.tolist(), look_target=centre.tolist(), eye_up=[0.0, 0.0, 1.0]
        )

    def fit(self, rr_blueprint: Any, aspect: float = 1.0, direction=EYE_DIRECTION) -> Any:
        """Camera looking at the box centre along ``direction`` from just far enough for every
        corner of the box to lie inside a view of width / height ``aspect`` (the viewer's
        vertical field of view, FOV_Y_DEG), so that what the box holds fills the view."""
        if self.empty:
            return None
        d = np.asarray(direction, dtype=float)
        d /= np.linalg.norm(d)
        right = np.cross(-d, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, -d)
        corners = (
            np.array(
                [[(a, b)[i] for a, b, i in zip(self.lo, self.hi, k, strict=True)] for k in CORNERS]
            )
            - (self.lo + self.hi) / 2
        )
        tan_y = math.tan(math.radians(FOV_Y_DEG) / 2)
        # a corner at depth z towards the eye, x right and y up is inside the view when the
        # eye stands at least z + |y| / tan_y (and z + |x| / (aspect tan_y)) from the centre
        reach = corners @ d + np.maximum(
            np.abs(corners @ up) / tan_y, np.abs(corners @ right) / (aspect * tan_y)
        )
        return self.eye(rr_blueprint, direction, FIT_MARGIN * float(np.max(reach)) / self.size)

    @property
    def size(self) -> float:
        """The box's largest side (metres), at least 5 cm."""
        return max(float(np.max(self.hi - self.lo)), 0.05)


@dataclass
class Series:
    """A curve under ``metrics/``: its time points, drawn as points or lines."""

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
class TargetGroup:
    """A pose group's targets: its view name, the machine it sits on, the box its view frames
    (targets, arrows, labels, tool head) and the targets' own box."""

    name: str
    machine: str = ""
    bounds: Bounds = field(default_factory=Bounds)
    targets: Bounds = field(default_factory=Bounds)

    @property
    def direction(self) -> tuple[float, float, float]:
        """From the view's centre to its eye: a flat layer of targets (its height under
        FLAT_SHARE of its width) seen from high above, so that it is not foreshortened and
        the head over it stays short; a volume of targets from the front, lower."""
        t = self.targets
        flat = not t.empty and float(np.ptp([t.lo[2], t.hi[2]])) < FLAT_SHARE * t.size
        return EYE_ABOVE if flat else EYE_DIRECTION


class SecondTimeline(ValueError):
    """A recording logged against a second timeline: its face would show the first's views
    empty (rerun plots and poses follow the one timeline selected)."""


@dataclass
class Logged:
    """What a study logged, in the order it logged it: the blueprint is built from this."""

    machines: list[str] = field(default_factory=list)  # "" is the machine under world/bodies
    timeline: str | None = None  # the one timeline (poses, per-pose curves)
    poses: set[int] = field(default_factory=set)  # its time points that place a machine
    target_groups: dict[str, TargetGroup] = field(default_factory=dict)  # path part -> group
    machine_bounds: Bounds = field(default_factory=Bounds)
    error_maps: dict[str, ErrorMap] = field(default_factory=dict)  # entity path -> map
    series: dict[str, Series] = field(default_factory=dict)  # entity path -> curve
    figures: dict[str, str] = field(default_factory=dict)  # entity path -> view name
    bars: dict[str, str] = field(default_factory=dict)  # entity path -> view name
    texts: dict[str, str] = field(default_factory=dict)  # entity path -> view name

    @property
    def mechanism(self) -> bool:
        return bool(self.machines)

    def use_timeline(self, timeline: str) -> None:
        """Note that data goes on ``timeline``; a second one raises :class:`SecondTimeline`."""
        if self.timeline is None:
            self.timeline = timeline
        elif timeline != self.timeline:
            raise SecondTimeline(
                f"the recording's timeline is '{self.timeline}'; logging against "
                f"'{timeline}' too would give it a face where the other views are empty: "
                f"draw that curve as a figure (Recorder.log_figure) or put it on "
                f"'{self.timeline}'"
            )

    def active_timeline(self) -> str | None:
        return self.timeline


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


def _machine_contents(machine: str) -> list[str]:
    root = f"world/{machine}/bodies" if machine else "world/bodies"
    return ["world", f"{root}/**"]


def machine_views(rrb: Any, log: Logged, aspect: float = 1.0) -> list[Any]:
    """One 3D view per pose group (its machine, its targets, arrows and labels), the camera
    framing the group's targets, arrows, labels and tool head in a view of width / height
    ``aspect``; a machine without targets gets a view of its own."""
    views = []
    for part, group in log.target_groups.items():
        contents = [*_machine_contents(group.machine), f"world/targets/{part}/**"]
        bounds = group.bounds if not group.bounds.empty else log.machine_bounds
        views.append(
            rrb.Spatial3DView(
                origin="world",
                contents=contents,
                name=group.name,
                eye_controls=bounds.fit(rrb, aspect, group.direction),
            )
        )
    shown = {g.machine for g in log.target_groups.values()}
    for machine in log.machines:
        if machine not in shown:
            views.append(
                rrb.Spatial3DView(
                    origin="world",
                    contents=_machine_contents(machine),
                    name=f"machine {machine}".strip(),
                    eye_controls=log.machine_bounds.eye(rrb),
                )
            )
    return views


def error_map_views(rrb: Any, log: Logged) -> Any | None:
    by_layer: dict[str, list[Any]] = {}
    for path, em in log.error_maps.items():
        view = rrb.Spatial3DView(
            origin=path,
            contents=["$origin/**"],
            name=f"{em.stage} ≤{em.vmax_mm:.2g} mm",
            eye_controls=em.bounds.eye(rrb, direction=(0.35, -0.6, 1.0)),
        )
        by_layer.setdefault(em.layer, []).append(view)
    rows = [  # a row of a few maps; more in tabs, where each title has room
        _row(rrb, views, name=f"error maps: {layer}")
        if len(views) <= 4
        else rrb.Tabs(*views, name=f"error maps: {layer}")
        for layer, views in by_layer.items()
    ]
    if not rows:
        return None
    return rows[0] if len(rows) == 1 else rrb.Tabs(*rows)


def figure_views(rrb: Any, log: Logged) -> list[Any]:
    return [
        rrb.Spatial2DView(origin=p, contents=["$origin"], name=n) for p, n in log.figures.items()
    ]


def series_views(rrb: Any, log: Logged) -> list[Any]:
    families: dict[str, list[str]] = {}
    for path in log.series:
        families.setdefault(_family(path), []).append(path)
    views = []
    timeline = (log.timeline or "").replace("_", " ")
    for family, paths in families.items():
        label = family.split("/", 1)[-1].replace("_", " ")
        views.append(
            rrb.TimeSeriesView(
                origin=family,
                contents=list(paths),
                name=f"{label} by {timeline}",
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


def _plots(rrb: Any, views: list[Any], alone: bool) -> Any | None:
    """Figures and curves: side by side up to two; beyond, in tabs beside a machine, or all
    at once in a grid when they are the recording's only pictures (``alone``)."""
    if not views:
        return None
    if len(views) <= 2:
        return _row(rrb, views)
    return rrb.Grid(*views, name="figures") if alone else rrb.Tabs(*views)


def _n_machine_views(log: Logged) -> int:
    shown = {g.machine for g in log.target_groups.values()}
    return len(log.target_groups) + sum(m not in shown for m in log.machines)


def view_aspect(n: int, width_share: float, height_share: float) -> float:
    """Width / height of each of ``n`` views in a row (a grid beyond three, as rerun lays it
    out) that takes ``width_share`` and ``height_share`` of a window of WINDOW pixels (a view's
    title bar off its height)."""
    cols = n if n <= 3 else math.ceil(math.sqrt(n))
    rows = math.ceil(n / cols)
    width, height = WINDOW
    return (width * width_share / cols) / max(height * height_share / rows - TITLE_BAR, 1.0)


def build_blueprint(log: Logged) -> Any:
    """The blueprint of a recording: the machine views and error maps on the left, the
    figures and plots and the text views on the right (with no error map, the plots take the
    error maps' place under the machine)."""
    import rerun.blueprint as rrb

    n_machine = _n_machine_views(log)
    maps = error_map_views(rrb, log)
    plots = _plots(rrb, figure_views(rrb, log) + series_views(rrb, log), not (n_machine or maps))
    texts = text_views(rrb, log)
    left_parts, left_shares = [], []
    right_parts, right_shares = [], []
    if n_machine:  # its views' shape from the layout, their cameras framed to fill them
        plots_left = plots is not None and maps is None
        left_height = 3.0 + 2.0 * (maps is not None) + 2.5 * plots_left
        two_columns = texts is not None or (plots is not None and not plots_left)
        aspect = view_aspect(n_machine, 5.0 / 9.0 if two_columns else 1.0, 3.0 / left_height)
        left_parts.append(_row(rrb, machine_views(rrb, log, aspect)))
        left_shares.append(3.0)
    if maps is not None:
        left_parts.append(maps)
        left_shares.append(2.0)
    if plots is not None:
        if n_machine and maps is None:
            left_parts.append(plots)
            left_shares.append(2.5)
        else:
            right_parts.append(plots)
            right_shares.append(1.5)
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
        root = rrb.Horizontal(*columns, column_shares=[5.0, 4.0])
    timeline = log.timeline
    panels = [
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        # paused on the first pose; no timeline: nothing to scrub through, no panel (it
        # would offer the viewer's own wall-clock timeline, with nothing on it)
        rrb.TimePanel(state="collapsed", timeline=timeline, play_state="paused")
        if timeline
        else rrb.TimePanel(state="hidden"),
    ]
    return rrb.Blueprint(root, *panels, auto_layout=False, auto_views=False)
