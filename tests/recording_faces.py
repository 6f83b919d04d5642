"""Reading a recording back as the viewer shows it: what the test modules that run a scenario
share to check its recording (test_recording, test_scenario_*, test_pose_selection, ...).

A *face* of a recording is its layout (the one blueprint) with one timeline selected: rerun
draws plots, poses and targets at the time of the selected timeline, static data on every one.
:func:`assert_every_face_has_data` checks, for every timeline of the recording (and with no
timeline at all), that every view of the layout has data to draw.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import pyarrow as pa
import rerun.chunk as rerun_chunk

# the studies whose recordings the test modules check, by the module that checks them: the
# registry test_recording_faces_cover_every_study holds against scenarios.runner.STUDIES
CHECKED = {
    "hexapod_paper": "test_scenario_hexapod",
    "liu_vs_ols": "test_scenario_liu_vs_ols",
    "liu_vs_ols_draws": "test_scenario_liu_vs_ols",
    "liu_regime": "test_liu_regime",
    "undeclared_effect": "test_scenario_undeclared_effect",
    "optimal_poses": "test_pose_selection",
    "serial_arm": "test_recording",
    "polisher_identifiability": "test_recording",
    "measured_loop": "test_recording",
    "iso9283": "test_iso9283_study",
    "diagnosis_benchmark": "test_diagnosis_benchmark",
    "sweep": "test_sweep",
}


class Readback:
    """Entity paths, the time points per timeline, and the data columns of an .rrd file."""

    def __init__(self, path: Path) -> None:
        reader = rerun_chunk.RrdReader(str(path))
        self.n_blueprints = len(reader.blueprints())
        store = reader.store()
        self.entities = set(store.schema().entity_paths())
        self.times: dict[str, set[int]] = defaultdict(set)  # timeline -> time points
        self.timelines: dict[str, set[str]] = defaultdict(set)  # entity -> its timelines
        self.static: dict[str, bool] = {}
        self.has_static: set[str] = set()
        self.rows: dict[tuple[str, str], list] = defaultdict(list)  # (entity, column)
        for chunk in store.stream():
            batch = chunk.to_record_batch()
            entity = chunk.entity_path
            self.static[entity] = chunk.is_static
            if chunk.is_static:
                self.has_static.add(entity)
            for field in batch.schema:
                kind = (field.metadata or {}).get(b"rerun:kind", b"").decode()
                if kind == "index":
                    self.timelines[entity].add(field.name)
                    column = batch.column(field.name)
                    if pa.types.is_timestamp(column.type):  # rerun's log_time, were it on
                        column = column.cast(pa.int64())
                    self.times[field.name].update(column.to_pylist())
                elif kind == "data":
                    self.rows[entity, field.name] += batch.column(field.name).to_pylist()


def blueprint(path: Path) -> tuple[str | None, list[dict]]:
    """The timeline the layout opens on and the views of the blueprint stored in an .rrd."""
    reader = rerun_chunk.RrdReader(str(path))
    (store,) = reader.blueprints()
    rows: dict[str, dict] = defaultdict(dict)
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        for field in batch.schema:
            if (field.metadata or {}).get(b"rerun:kind", b"").decode() == "data":
                rows[chunk.entity_path][field.name] = batch.column(field.name).to_pylist()[-1]
    timeline = rows.get("/time_panel", {}).get("TimePanelBlueprint:timeline", [None])[0]
    views = []
    for entity, r in rows.items():
        if "ViewBlueprint:class_identifier" in r:
            origin = r["ViewBlueprint:space_origin"][0]
            queries = rows[f"{entity}/ViewContents"]["ViewContents:query"]
            views.append(
                {
                    "kind": r["ViewBlueprint:class_identifier"][0],
                    "name": r["ViewBlueprint:display_name"][0],
                    "queries": [q.replace("$origin", origin) for q in queries],
                }
            )
    return timeline, views


def matches(entity: str, query: str) -> bool:
    e, q = entity.strip("/"), query.strip("/")
    if q.endswith("/**"):
        root = q[:-3]
        return e == root or e.startswith(root + "/")
    return e == q


def assert_every_face_has_data(path: Path) -> list[dict]:
    """For every timeline of the recording at ``path`` (rerun's wall-clock ones included,
    were they there), every view of its layout shows data on it (time data on that timeline,
    or static data); a plot's curves are on it with more than one point or drawn as
    markers; a machine view's bodies and each pose group's targets are placed on it.
    Returns the views."""
    rb = Readback(path)
    opens_on, views = blueprint(path)
    assert views, f"{path.name}: no view in its layout"
    timelines = sorted(rb.times)
    assert opens_on in ([*timelines, None] if not timelines else timelines), (opens_on, timelines)
    with_data = {e for (e, _c) in rb.rows}
    for timeline in timelines or [None]:
        for view in views:
            shown = [e for e in with_data if any(matches(e, q) for q in view["queries"])]
            live = [e for e in shown if e in rb.has_static or timeline in rb.timelines[e]]
            assert live, f"{path.name}: view '{view['name']}' has no data on {timeline}"
            if view["kind"] == "TimeSeries":
                curves = [e for e in shown if (e, "Scalars:scalars") in rb.rows]
                assert curves, view["name"]
                for e in curves:
                    assert timeline in rb.timelines[e], (path.name, view["name"], e, timeline)
                    n = len(rb.rows[e, "Scalars:scalars"])
                    assert n > 1 or (e, "SeriesPoints:markers") in rb.rows, (view["name"], e)
            if view["kind"] == "3D":
                bodies = [e for e in shown if _is_body(e)]
                if bodies:
                    placed = [
                        e for e in bodies if e in rb.has_static or timeline in rb.timelines[e]
                    ]
                    assert len(placed) == len(bodies), (path.name, view["name"], timeline)
                targets = [e for e in shown if e.startswith("/world/targets/")]
                for e in targets:
                    assert timeline in rb.timelines[e] or e in rb.has_static, (view["name"], e)
            if view["kind"] == "2D":
                assert any((e, "EncodedImage:blob") in rb.rows for e in live), view["name"]
    return views


def _is_body(entity: str) -> bool:
    """``/world/bodies/<body>`` or ``/world/<machine>/bodies/<body>`` (not a geom below)."""
    parts = entity.strip("/").split("/")
    return (len(parts) == 3 and parts[1] == "bodies") or (len(parts) == 4 and parts[2] == "bodies")
