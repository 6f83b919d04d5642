"""The rerun recording of a scenario, read back with rerun's own reader (rerun.chunk)."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from recording_faces import CHECKED, Readback, assert_every_face_has_data, blueprint

from scenarios.recording.blueprints import (
    CORNERS,
    EYE_ABOVE,
    FIT_MARGIN,
    FOV_Y_DEG,
    Bounds,
    SecondTimeline,
)
from scenarios.recording.parts import error_colors
from scenarios.recording.recorder import Recorder
from scenarios.recording.targets import ARROW_SHARE, arrow_scale, label_positions
from twin.kinematics.single_pose import forward
from twin.mechanism import Mechanism

ROOT = Path(__file__).resolve().parent.parent
HEXAPOD = ROOT / "models" / "hexapod_rrrprr.xml"


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
            rec.log_metric("lm_cost/fit", "pose", 0, 3.0)
            rec.log_metric("lm_cost/fit", "pose", 1, 0.5)
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
        "/world/targets/cal/measured_magnified",
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
    # the study's timeline only: rerun's wall-clock ones are off
    assert set(rb.times) == {"pose"} and rb.times["pose"] == {0, 1, 2}
    assert rb.timelines["/metrics/lm_cost/fit"] == {"pose"}
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
    labels = rb.rows["/world/targets/cal/error_mm", "Points3D:labels"][0]
    assert labels == ["0.022 mm"] * len(vectors)  # |(0.01, 0, -0.02)| mm, beside each target
    at = np.array(rb.rows["/world/targets/cal/error_mm", "Points3D:positions"][0])
    assert len(np.unique(np.round(at, 6), axis=0)) == len(at)  # no two labels in one place
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
        rec.log_figure("f", b"not drawn", "figure")
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
        rec.log_metric("residual/fit", "pose", 0, 3.0)
        rec.log_metric("residual/fit", "pose", 1, 1.0)
        rec.log_points("heldout/one", "pose", 0, 1.0)
        rec.log_figure("cost", _png(), "cost by iteration")  # a curve not against the poses
        rec.log_text("verdict", "**fine**")
    views = assert_every_face_has_data(path)
    names = [v["name"] for v in views]
    assert "before: errors x100" in names
    assert "before ≤2 mm" in names  # the stage first, its scale's maximum
    assert {"parameters: fit", "verdict", "cost by iteration"} <= set(names)
    assert blueprint(path)[0] == "pose"
    assert Readback(path).times.keys() == {"pose"}


def _png() -> bytes:
    from scenarios.figures import plt, png_bytes

    fig, ax = plt.subplots(figsize=(2, 2))
    ax.semilogy([1, 2, 3], [1e-2, 1e-5, 1e-9])
    return png_bytes(fig)


def test_a_second_timeline_is_refused(tmp_path):
    """A curve against another variable than the poses would give the recording a face (that
    timeline selected) where the machine views are empty: it must be a figure."""
    mech = Mechanism.from_xml(HEXAPOD)
    with Recorder(tmp_path / "two.rrd", "two") as rec:
        rec.log_pose("pose", 0, mech, mech.home_qpos)
        with pytest.raises(SecondTimeline, match="log_figure"):
            rec.log_metric("lm_cost", "lm_iteration", 0, 1.0)
        with pytest.raises(SecondTimeline):
            rec.log_targets("node", 0, np.zeros((1, 3)), np.ones((1, 3)))
    assert Readback(tmp_path / "two.rrd").times.keys() == {"pose"}


def test_a_face_without_data_is_caught(tmp_path):
    """The read-back check fails on the recordings this project used to write: a plot on one
    timeline and the machine on another (either face has an empty view)."""
    import rerun as rr
    import rerun.blueprint as rrb

    path = tmp_path / "old.rrd"
    rec = rr.RecordingStream("old")
    rec.save(path)
    rec.set_log_time_enabled(False)
    rec.set_time("lm_iteration", sequence=0)
    rec.log("metrics/cost", rr.Scalars(1.0))
    rec.set_time("lm_iteration", sequence=1)
    rec.log("metrics/cost", rr.Scalars(0.5))
    rec.reset_time()
    rec.set_time("node", sequence=0)
    rec.log("world/targets/a/nominal", rr.Points3D([[0.0, 0.0, 0.0]]))
    rec.send_blueprint(
        rrb.Blueprint(
            rrb.Horizontal(
                rrb.TimeSeriesView(origin="metrics", name="cost"),
                rrb.Spatial3DView(origin="world", name="machine"),
            ),
            rrb.TimePanel(timeline="lm_iteration"),
        )
    )
    rec.disconnect()
    with pytest.raises(AssertionError, match="no data on"):
        assert_every_face_has_data(path)


def test_arrows_are_magnified_to_be_seen_and_labels_set_apart():
    nominal = np.array([[[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.2, 0.0]]])
    measured = nominal + np.array([0.0, 0.0, 30e-6])  # 30 um on a 0.2 m target set
    scale = arrow_scale(nominal, measured)
    assert scale in (1e3, 2e3, 5e3)  # a 1-2-5 factor
    # rounded down to a 1-2-5 factor, the arrow is between 2/5 of ARROW_SHARE and all of it
    assert 0.4 * ARROW_SHARE * 0.2 <= 30e-6 * scale <= ARROW_SHARE * 0.2
    at = label_positions(nominal, 0.2)[0]
    gaps = np.linalg.norm(at[:, None] - at[None], axis=-1)[np.triu_indices(3, 1)]
    assert gaps.min() > 0.02  # apart from each other
    assert np.all(np.linalg.norm(at - nominal[0], axis=1) > 0.005)  # and off their targets
    assert arrow_scale(nominal, nominal) == 1.0


@pytest.mark.parametrize("name", ["serial_arm", "polisher_identifiability", "measured_loop"])
def test_scenario_recordings_show_data_in_every_face(tmp_path, name):
    """The studies no other test module runs with a recording (see recording_faces.CHECKED)."""
    from scenarios.runner import run_scenario

    _, out = run_scenario(name, tmp_path / "results", quiet=True)
    views = assert_every_face_has_data(out / f"{name}.rrd")
    names = " | ".join(v["name"] for v in views)
    assert "report: key numbers" in names
    if name == "serial_arm":  # both variants on the one pose timeline, each its own arm
        assert "one reflector: errors x" in names and "three reflectors: errors x" in names
        rb = Readback(out / f"{name}.rrd")
        assert rb.times.keys() == {"pose"}
        assert "/world/one_reflector/bodies/link6" in rb.entities
        assert "/world/three_reflectors/bodies/link6" in rb.entities
    elif name == "polisher_identifiability":  # the singular values on a log axis, static
        assert "singular values of H" in names
        # what the plan cannot see, as counts per limb and the coupled groups named
        assert "what the plan cannot see" in names and "read only as combinations" in names
        assert Readback(out / f"{name}.rrd").times.keys() == {"node"}
    elif name == "measured_loop":  # two figures side by side, not three
        figures = {v["name"] for v in views if v["kind"] == "2D"}
        assert figures == {
            "diagnose: the residual against what explains it",
            "verify: the test set at each step",
        }


def test_recording_faces_cover_every_study():
    """Every study's recording is read back face by face by some test module."""
    from scenarios.runner import STUDIES

    assert set(STUDIES) | {"liu_vs_ols_draws", "sweep"} == set(CHECKED)
    for module in set(CHECKED.values()):
        text = (ROOT / "tests" / f"{module}.py").read_text()
        assert "assert_every_face_has_data(" in text, module


def test_log_poses_sends_what_log_pose_logs(tmp_path, monkeypatch):
    """log_poses sends each body's transforms and each target entity of all poses as one
    column: read back, the same transforms, points and arrows (labels included) at the same
    time points as pose-by-pose log_pose and log_targets."""
    monkeypatch.setenv("RERUN_STRICT", "1")
    mech = Mechanism.from_xml(HEXAPOD)
    home = mech.home_qpos[mech.actuator_qpos]
    qs = np.array([forward(mech, home + 0.002 * k).qpos for k in range(3)])
    # two targets 1 cm apart moving 1 mm a pose: one pose's spread and all poses' are the
    # smallest one (5 cm), so label offsets and radii agree pose by pose and at once
    nominal = (
        np.array([[[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]] for _ in range(3)])
        + np.arange(3)[:, None, None] * 1e-3
    )
    measured = nominal + 1e-5
    back = {}
    for how in ("columns", "one_by_one"):
        path = tmp_path / f"{how}.rrd"
        with Recorder(path, "pkm-calib-test") as rec:
            if how == "columns":
                rec.log_poses("pose", [4, 5, 6], mech, qs, nominal, measured, "cal", 100.0)
            else:
                for k, q, a, b in zip([4, 5, 6], qs, nominal, measured, strict=True):
                    rec.log_pose("pose", k, mech, q)
                    rec.log_targets("pose", k, a, b, group="cal")
            assert rec.logged.poses == {4, 5, 6} and rec.logged.timeline == "pose"
        back[how] = Readback(path)
    a, b = back["columns"], back["one_by_one"]
    assert a.entities == b.entities and a.times["pose"] == b.times["pose"] == {4, 5, 6}
    bodies = [e for e in a.entities if e.startswith("/world/bodies/")]
    assert bodies
    compared = [k for k in b.rows if k[0] in bodies or k[0].startswith("/world/targets/")]
    assert len(compared) > len(bodies)  # the transforms and the targets' points and arrows
    for key in compared:
        assert a.rows[key] == b.rows[key], key


def test_a_field_of_nodes_states_its_magnification_from_the_data(tmp_path):
    """Errors of micrometres on nodes spread 0.2 m: the largest arrow drawn at most 30 % of
    the field's extent, a 1-2-5 factor (0.06 m / 40 um = 1500 -> 1000), named in the view
    (no legend in the scene); the view framed on the field and the tool head."""
    from scenarios.recording.targets import field_scale

    mech = Mechanism.from_xml(HEXAPOD)
    xy = np.stack(np.meshgrid([0.0, 0.1, 0.2], [0.0, 0.1]), axis=-1).reshape(-1, 2)
    nominal = np.column_stack([xy, np.full(6, 0.3)])
    measured = nominal + np.outer(np.linspace(10e-6, 40e-6, 6), [1.0, 0.0, 0.0])
    scale = field_scale(nominal, measured)
    assert scale == 1000.0 and 40e-6 * scale <= 0.3 * 0.2 < 40e-6 * 2000
    assert field_scale(nominal, nominal + 100 * (measured - nominal)) == 10.0  # 0.06 / 4 mm
    qpos = np.repeat(mech.home_qpos[None], 6, axis=0)
    with Recorder(tmp_path / "f.rrd", "field") as rec:
        rec.send_blueprint()
        rec.log_mechanism(mech)
        rec.log_poses("node", range(6), mech, qpos, nominal, measured, "ols", scale, field=True)
        group = rec.logged.target_groups["ols"]
    names = [v["name"] for v in assert_every_face_has_data(tmp_path / "f.rrd")]
    assert "ols: errors x1000" in names
    entities = set(Readback(tmp_path / "f.rrd").entities)
    assert {"/world/targets/ols/field", "/world/targets/ols/error_mm/leader"} <= entities
    assert not any("legend" in e for e in entities)
    # the targets lie flat (one height): the view looks from high above; its box holds the
    # targets and the tool head at the first pose (the centres of the tool body's geoms)
    assert group.direction == EYE_ABOVE
    m, d = mech.model, mujoco.MjData(mech.model)
    d.qpos[:] = qpos[0]
    mujoco.mj_kinematics(m, d)
    head = d.geom_xpos[m.geom_bodyid == mech.tool_body]
    assert len(head) and np.all(group.bounds.lo <= head) and np.all(head <= group.bounds.hi)
    assert np.all(group.bounds.lo <= nominal.min(axis=0))


@pytest.mark.parametrize("aspect", [0.5, 1.0, 1.8])
def test_a_machine_view_is_framed_to_fill_it(aspect):
    """From 1 / FIT_MARGIN of the eye's distance every corner of the box is inside the field of
    view (vertical FOV_Y_DEG, horizontal from the aspect) and one on its edge: the tightest
    fit; from the eye itself all are inside."""
    import rerun.blueprint as rrb

    box = Bounds()
    box.add(np.array([[-0.3, -0.2, 0.0], [0.2, 0.3, 0.7]]))
    eye = box.fit(rrb, aspect, EYE_ABOVE)
    position = np.asarray(eye.position.as_arrow_array().to_pylist()[0])
    target = np.asarray(eye.look_target.as_arrow_array().to_pylist()[0])
    assert np.allclose(target, (box.lo + box.hi) / 2)
    corners = np.array([[(box.lo, box.hi)[k][i] for i, k in enumerate(c)] for c in CORNERS])

    def used(eye_at: np.ndarray) -> np.ndarray:
        """Each corner's offset from the view's centre over the half-view (1: on the edge)."""
        forward = (target - eye_at) / np.linalg.norm(target - eye_at)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        rel = corners - eye_at
        tan_y = np.tan(np.radians(FOV_Y_DEG) / 2)
        edge = np.maximum(np.abs(rel @ up) / tan_y, np.abs(rel @ right) / (aspect * tan_y))
        return edge / (rel @ forward)

    tight = used(target + (position - target) / FIT_MARGIN)
    # 1e-6: the eye is stored in float32 (a relative rounding of 6e-8 per coordinate)
    assert np.all(tight <= 1 + 1e-6) and np.max(tight) > 1 - 1e-6
    assert np.all(used(position) < 1)
