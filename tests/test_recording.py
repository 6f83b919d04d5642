"""The rerun recording of a scenario, read back with rerun's own reader (rerun.chunk)."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import mujoco
import numpy as np
import pytest

from scenarios.config import find_scenario
from scenarios.recording.charts import error_colors
from scenarios.recording.recorder import Recorder
from twin.kinematics.single_pose import forward
from twin.mechanism import Mechanism

ROOT = Path(__file__).resolve().parent.parent
HEXAPOD = ROOT / "models" / "hexapod_rrrprr.xml"
rerun_chunk = pytest.importorskip("rerun.chunk")


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
                if kind == "index" and field.name != "log_time":
                    self.timelines[entity].add(field.name)
                    self.times[field.name].update(batch.column(field.name).to_pylist())
                elif kind == "data":
                    self.rows[entity, field.name] += batch.column(field.name).to_pylist()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[Readback, Mechanism, list[np.ndarray]]:
    mp = pytest.MonkeyPatch()
    mp.setenv("RERUN_STRICT", "1")  # a logging mistake raises instead of warning
    try:
        mech = Mechanism.from_xml(HEXAPOD)
        home = mech.home_qpos[mech.actuator_qpos]
        qs = [
            mech.home_qpos.copy(),
            forward(mech, home + 0.004).qpos,
            forward(mech, home + 0.003 * np.array([1, -1, 1, -1, 1, -1])).qpos,
        ]
        path = tmp_path_factory.mktemp("rrd") / "x.rrd"
        with Recorder(path, "pkm-calib-test") as rec:
            rec.send_blueprint()
            rec.log_mechanism(mech)
            for i, q in enumerate(qs):
                rec.log_pose("pose", i, mech, q)  # runs mj_kinematics on mech.data
                targets = mech.data.site_xpos[mech.target_sites].copy()
                rec.log_targets(
                    "pose", i, targets, targets + np.array([1e-5, 0.0, -2e-5]), group="cal"
                )
                rec.log_metric("closure_residual", "pose", i, 1e-15 * (i + 1))
            grid = np.stack(np.meshgrid([-0.02, 0, 0.02], [-0.02, 0, 0.02], [0.22]), -1)
            rec.log_error_map("before", "layer_220", grid.reshape(-1, 3), np.arange(9.0) / 100)
            rec.log_parameters(
                "fit", ["leg1.dl", "leg2.dl"], np.array([0.1, -0.2]), np.array([0.01, np.nan])
            )
            rec.log_metric("lm_cost/fit", "lm_iteration", 0, 3.0)
            rec.log_metric("lm_cost/fit", "lm_iteration", 1, 0.5)
            rec.log_points("single", "pose", 0, 1.0)  # one point: drawn as a marker
            rec.log_text("verdict", "# Residual\n\n* white")
        assert path.stat().st_size > 0
        return Readback(path), mech, qs
    finally:
        mp.undo()


def test_expected_entities_exist(recorded):
    rb, mech, _ = recorded
    assert rb.n_blueprints == 1
    for expected in (
        "/world/bodies/platform",
        "/world/bodies/leg3_rod",
        "/world/bodies/world/base_plate",
        "/world/targets/cal/nominal",
        "/world/targets/cal/measured",
        "/world/targets/cal/error",
        "/error_maps/before/layer_220/nodes",
        "/error_maps/before/layer_220/scale_mm",
        "/parameters/fit",
        "/metrics/closure_residual",
        "/metrics/lm_cost/fit",
        "/verdict",
    ):
        assert expected in rb.entities, expected
    geoms = [e for e in rb.entities if e.startswith("/world/bodies/") and e.count("/") == 4]
    assert len(geoms) == mech.model.ngeom  # every hexapod geom has a shape
    assert all(rb.static[e] for e in geoms)


def _platform_pose(mech: Mechanism, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mech.data.qpos[:] = q
    mujoco.mj_kinematics(mech.model, mech.data)
    b = mech.model.body("platform").id
    return mech.data.xpos[b].copy(), mech.data.xquat[b].copy()


def test_pose_timeline_and_body_transforms(recorded):
    rb, mech, qs = recorded
    assert rb.times["pose"] == {0, 1, 2}
    assert rb.times["lm_iteration"] == {0, 1}
    # each call carries its own timeline only (a metric does not inherit the pose's time)
    assert rb.timelines["/metrics/lm_cost/fit"] == {"lm_iteration"}
    # the viewer opens on "pose" (most curves): the machine is not copied to other timelines
    assert rb.timelines["/world/bodies/platform"] == {"pose"}
    entity = "/world/bodies/platform"
    logged_p = np.array([t[0] for t in rb.rows[entity, "Transform3D:translation"]])
    logged_q = np.array([t[0] for t in rb.rows[entity, "Transform3D:quaternion"]])
    assert logged_p.shape == (3, 3) and logged_q.shape == (3, 4)
    for k, q in enumerate(qs):
        p, wxyz = _platform_pose(mech, q)
        np.testing.assert_allclose(logged_p[k], p, atol=1e-6)  # world coordinates
        np.testing.assert_allclose(logged_q[k], np.roll(wxyz, -1), atol=1e-6)  # xyzw
    assert np.ptp(logged_p[:, 2]) > 1e-3  # the poses differ


def test_geom_shapes_sit_in_body_coordinates(recorded):
    rb, mech, _ = recorded
    capsules = [e for (e, c) in rb.rows if c == "Capsules3D:lengths"]
    assert capsules
    for entity in capsules:  # rerun's capsule starts at its origin: shifted to be centred
        length = rb.rows[entity, "Capsules3D:lengths"][0][0]
        shift = rb.rows[entity, "Capsules3D:translations"][0][0]
        assert length > 0 and shift == pytest.approx([0, 0, -length / 2], rel=1e-6)
    plate = "/world/bodies/world/base_plate"
    np.testing.assert_allclose(
        rb.rows[plate, "Transform3D:translation"][0][0], mech.model.geom("base_plate").pos
    )
    assert rb.rows[plate, "Cylinders3D:radii"][0][0] == pytest.approx(
        mech.model.geom("base_plate").size[0]
    )


def test_targets_error_map_and_parameters_values(recorded):
    rb, _, _ = recorded
    vectors = np.array(rb.rows["/world/targets/cal/error", "Arrows3D:vectors"][0])
    np.testing.assert_allclose(vectors, np.tile([1e-3, 0.0, -2e-3], (len(vectors), 1)), atol=1e-8)
    assert "x100" in rb.rows["/world/targets/cal/error", "Arrows3D:labels"][0][0]
    nodes = "/error_maps/before/layer_220/nodes"
    labels = rb.rows[nodes, "Points3D:labels"][0]
    assert labels[0] == "0.000 mm" and labels[-1] == "0.080 mm"
    assert len(set(rb.rows[nodes, "Points3D:colors"][0])) == 9
    assert rb.static[nodes]
    radius = rb.rows[nodes, "Points3D:radii"][0][0]
    assert radius <= 0.3 * 0.02 + 1e-9  # spheres smaller than the 20 mm node spacing
    ticks = rb.rows["/error_maps/before/layer_220/scale_mm/ticks", "Points3D:labels"][0]
    assert ticks == ["0 mm", "0.08 mm"]  # the colour scale, in mm
    table = rb.rows["/parameters/fit", "TextDocument:text"][0][0]
    assert "| leg2.dl | -0.2 | nan |" in table
    scalars = rb.rows["/metrics/lm_cost/fit", "Scalars:scalars"]
    assert [s[0] for s in scalars] == [3.0, 0.5]


def test_error_colors_span_viridis_and_grey_nan():
    c = error_colors(np.array([0.0, 1.0, 2.0, np.nan]), vmax=1.0)
    assert c.dtype == np.uint8 and c.shape == (4, 3)
    np.testing.assert_array_equal(c[1], c[2])  # clipped at vmax
    assert tuple(c[0]) == (68, 1, 84)  # viridis(0)
    assert tuple(c[3]) == (128, 128, 128)


@pytest.mark.parametrize("strict", ["1", "0"])
def test_strict_mode_is_read_when_the_recorder_is_made(tmp_path, monkeypatch, strict):
    monkeypatch.setenv("RERUN_STRICT", strict)
    with Recorder(tmp_path / "s.rrd", "strict") as rec:
        bad = np.zeros((2, 2))  # positions must be (N, 3)
        if strict == "1":
            with pytest.raises(ValueError, match="multiple of 3"):
                rec.log_error_map("s", "l", bad, np.ones(2))
        else:
            with pytest.warns(Warning, match="multiple of 3"):  # a RerunWarning
                rec.log_error_map("s", "l", bad, np.ones(2))
        rec.log_metric("m", "t", 0, 1.0)  # the recorder still works
    assert "/metrics/m" in Readback(tmp_path / "s.rrd").entities


def test_disabled_recorder_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    mech = Mechanism.from_xml(HEXAPOD)
    with Recorder(None, "nothing") as rec:
        assert not rec.enabled
        rec.send_blueprint()
        rec.log_mechanism(mech)
        rec.log_pose("pose", 0, mech, mech.home_qpos)
        rec.log_targets("pose", 0, np.zeros((3, 3)), np.ones((3, 3)))
        rec.log_error_map("s", "l", np.zeros((2, 3)), np.ones(2))
        rec.log_parameters("s", ["a"], np.ones(1), None, np.ones(1))
        rec.log_points("p", "t", 0, 1.0)
        rec.log_bars("b", ["a"], np.ones(1), "mm")
        rec.log_report("undeclared_effect", {})
        rec.log_metric("x", "t", 0, 1.0)
        rec.log_text("t", "text")
    rec.close()  # idempotent
    assert list(tmp_path.iterdir()) == []


def test_a_reports_figures_are_named_not_shown_as_broken_images(tmp_path):
    """The viewer cannot open a figure beside the recording: its link becomes its name."""
    path = tmp_path / "r.rrd"
    with Recorder(path, "report") as rec:
        rec.log_text("report", "# R\n\n![error maps](maps.png)\n\n![web](https://x.org/a.png)")
    text = Readback(path).rows["/report", "TextDocument:text"][0][0]
    assert "![error maps]" not in text
    assert "*Figure: error maps (`maps.png`, beside the recording)*" in text
    assert "![web](https://x.org/a.png)" in text  # a link the viewer can follow stays


def test_close_is_idempotent_and_file_readable(tmp_path):
    path = tmp_path / "sub" / "y.rrd"
    rec = Recorder(path, "twice")
    rec.log_metric("m", "t", 0, 1.0)
    rec.close()
    rec.close()
    rec.log_metric("m", "t", 1, 2.0)  # after close: a no-op, not an error
    rb = Readback(path)
    assert rb.times["t"] == {0} and rb.n_blueprints == 0


def _blueprint(path: Path) -> tuple[str, list[dict]]:
    """The active timeline and the views of the blueprint stored in an .rrd file."""
    reader = rerun_chunk.RrdReader(str(path))
    (store,) = reader.blueprints()
    rows: dict[str, dict] = defaultdict(dict)
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        for field in batch.schema:
            if (field.metadata or {}).get(b"rerun:kind", b"").decode() == "data":
                rows[chunk.entity_path][field.name] = batch.column(field.name).to_pylist()[-1]
    timeline = rows["/time_panel"]["TimePanelBlueprint:timeline"][0]
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


def _matches(entity: str, query: str) -> bool:
    e, q = entity.strip("/"), query.strip("/")
    if q.endswith("/**"):
        root = q[:-3]
        return e == root or e.startswith(root + "/")
    return e == q


def assert_every_view_has_data(rb: Readback, path: Path) -> list[dict]:
    """Each view of the blueprint shows data on the active timeline (or static data); each
    curve in a plot has more than one point or is drawn as points."""
    timeline, views = _blueprint(path)
    assert views
    with_data = {e for (e, _c) in rb.rows}
    for view in views:
        shown = [e for e in with_data if any(_matches(e, q) for q in view["queries"])]
        live = [e for e in shown if timeline in rb.timelines[e] or e in rb.has_static]
        assert live, f"view '{view['name']}' has no data on timeline {timeline}"
        if view["kind"] == "TimeSeries":
            curves = [e for e in shown if (e, "Scalars:scalars") in rb.rows]
            assert curves, view["name"]
            for e in curves:
                assert timeline in rb.timelines[e], (view["name"], e)
                n = len(rb.rows[e, "Scalars:scalars"])
                assert n > 1 or (e, "SeriesPoints:markers") in rb.rows, (view["name"], e, n)
        if view["kind"] == "3D" and any(q.startswith("world/bodies") for q in view["queries"]):
            bodies = [e for e in shown if e.count("/") == 3 and timeline in rb.timelines[e]]
            assert bodies or any(e in rb.has_static for e in shown), view["name"]
    return views


def test_the_blueprint_is_built_from_what_was_logged(tmp_path):
    path = tmp_path / "bp.rrd"
    mech = Mechanism.from_xml(HEXAPOD)
    with Recorder(path, "bp") as rec:
        rec.send_blueprint()
        rec.log_mechanism(mech)
        for i in range(3):
            rec.log_pose("pose", i, mech, mech.home_qpos)
            t = mech.data.site_xpos[mech.target_sites].copy()
            rec.log_targets("pose", i, t, t + 1e-5, group="before")
        rec.log_error_map("before", "grid", np.eye(3) * 0.02, np.arange(3.0))
        rec.log_parameters("fit", ["a", "b"], np.ones(2), np.ones(2), np.zeros(2))
        rec.log_metric("lm_cost/fit", "lm_iteration", 0, 3.0)
        rec.log_metric("lm_cost/fit", "lm_iteration", 1, 1.0)
        rec.log_points("heldout/one", "lm_iteration", 0, 1.0)
        rec.log_metric("elsewhere", "other", 0, 1.0)  # not on the active timeline: no view
        rec.log_text("verdict", "**fine**")
    views = assert_every_view_has_data(Readback(path), path)
    names = [v["name"] for v in views]
    assert "before: machine, targets and error arrows" in names
    assert any(n.startswith("before / grid, 0-2 mm") and n.endswith(": error map") for n in names)
    assert {"parameters: fit", "verdict"} <= set(names)
    assert not any("elsewhere" in n for n in names)
    assert _blueprint(path)[0] == "lm_iteration"  # most curves are plotted against it
    rb = Readback(path)  # and the machine is placed on it too (its first pose)
    assert rb.timelines["/world/bodies/platform"] == {"pose", "lm_iteration"}


SMALLER = {  # the scenario, cut down to seconds: (section, key, full value, smaller value)
    "hexapod_paper": [
        ("plans", "many_poses", "256", "40"),
        ("verification", "nodes_per_axis", "3", "2"),
        ("verification", "orientations_per_node", "8", "2"),
    ],
}


def _scenario_copy(name: str, tmp_path: Path) -> str:
    """The shipped scenario file, or a copy with fewer poses (relative paths still resolve
    from scenarios/ and the repository)."""
    text = find_scenario(name).read_text()
    if name not in SMALLER:
        return name
    for _section, key, full, small in SMALLER[name]:
        old = f"{key} = {full}"
        assert old in text, old
        text = text.replace(old, f"{key} = {small}")
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("name", ["hexapod_paper", "serial_arm"])  # and undeclared_effect's:
def test_scenario_recordings_show_data_in_every_view(tmp_path, name):  # in its own module
    from scenarios.runner import run_scenario

    _, out = run_scenario(_scenario_copy(name, tmp_path), tmp_path / "results", quiet=True)
    path = out / f"{name}.rrd"
    rb = Readback(path)
    views = assert_every_view_has_data(rb, path)
    names = " | ".join(v["name"] for v in views)
    assert "report: key numbers" in names
    if name == "hexapod_paper":  # one error map per stage, the LM cost per iteration
        for stage in ("before", "after_random_few", "after_random_many"):
            assert f"{stage} / verification_grid" in names
        assert rb.times["lm_iteration"] and len(rb.times["lm_iteration"]) > 1
    else:  # two variants on their own pose timelines: the view of the one opened on only
        assert _blueprint(path)[0] == "one_reflector_pose"
        assert "one_reflector: machine, targets and error arrows" in names
        assert "three_reflectors" not in names
        assert rb.times["three_reflectors_pose"]
        assert any(c == "Capsules3D:lengths" for (_e, c) in rb.rows)  # the arm is drawn


def test_log_poses_sends_what_log_pose_logs(tmp_path, monkeypatch):
    """log_poses sends each body's transforms and each target entity of all poses as one
    column: read back, the same transforms, points and arrows (labels included) at the same
    time points as pose-by-pose log_pose and log_targets."""
    monkeypatch.setenv("RERUN_STRICT", "1")
    mech = Mechanism.from_xml(HEXAPOD)
    home = mech.home_qpos[mech.actuator_qpos]
    qs = np.array([forward(mech, home + 0.002 * k).qpos for k in range(3)])
    nominal = np.array([np.zeros((2, 3)) + k for k in range(3)])
    measured = nominal + 1e-5
    back = {}
    for how in ("columns", "one_by_one"):
        path = tmp_path / f"{how}.rrd"
        with Recorder(path, "pkm-calib-test") as rec:
            if how == "columns":
                rec.log_poses("pose", [4, 5, 6], mech, qs, nominal, measured, "cal")
            else:
                for k, q, a, b in zip([4, 5, 6], qs, nominal, measured, strict=True):
                    rec.log_pose("pose", k, mech, q)
                    rec.log_targets("pose", k, a, b, group="cal")
            assert rec.logged.pose_timelines["pose"] == {4, 5, 6}
        back[how] = Readback(path)
    a, b = back["columns"], back["one_by_one"]
    assert a.entities == b.entities and a.times["pose"] == b.times["pose"] == {4, 5, 6}
    bodies = [e for e in a.entities if e.startswith("/world/bodies/")]
    assert bodies
    compared = [k for k in b.rows if k[0] in bodies or k[0].startswith("/world/targets/")]
    assert len(compared) > len(bodies)  # the transforms and the targets' points and arrows
    for key in compared:
        assert a.rows[key] == b.rows[key], key
