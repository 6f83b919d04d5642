"""The rerun recording of a scenario, read back with rerun's own reader (rerun.chunk)."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import mujoco
import numpy as np
import pytest

from scenarios.recording import Recorder, error_colors
from twin.kinematics import forward
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
        self.rows: dict[tuple[str, str], list] = defaultdict(list)  # (entity, column)
        for chunk in store.stream():
            batch = chunk.to_record_batch()
            entity = chunk.entity_path
            self.static[entity] = chunk.is_static
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
                rec.log_targets("pose", i, targets, targets + np.array([1e-5, 0.0, -2e-5]))
                rec.log_metric("closure_residual", "pose", i, 1e-15 * (i + 1))
            grid = np.stack(np.meshgrid([-0.02, 0, 0.02], [-0.02, 0, 0.02], [0.22]), -1)
            rec.log_error_map("before", "layer_220", grid.reshape(-1, 3), np.arange(9.0) / 100)
            rec.log_parameters(
                "fit", ["leg1.dl", "leg2.dl"], np.array([0.1, -0.2]), np.array([0.01, np.nan])
            )
            rec.log_metric("lm_cost/fit", "lm_iteration", 0, 3.0)
            rec.log_metric("lm_cost/fit", "lm_iteration", 1, 0.5)
            rec.log_text("diagnosis", "# Residual\n\n* white")
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
        "/world/targets/nominal",
        "/world/targets/measured",
        "/world/targets/error",
        "/error_maps/before/layer_220",
        "/parameters/fit/estimate",
        "/parameters/fit/std",
        "/parameters/fit/table",
        "/metrics/closure_residual",
        "/metrics/lm_cost/fit",
        "/diagnosis",
    ):
        assert expected in rb.entities, expected
    assert "/parameters/fit/truth" not in rb.entities  # no truth given
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
    vectors = np.array(rb.rows["/world/targets/error", "Arrows3D:vectors"][0])
    np.testing.assert_allclose(vectors, np.tile([1e-3, 0.0, -2e-3], (len(vectors), 1)), atol=1e-8)
    assert "x100" in rb.rows["/world/targets/error", "Arrows3D:labels"][0][0]
    labels = rb.rows["/error_maps/before/layer_220", "Points3D:labels"][0]
    assert labels[0] == "0.000 mm" and labels[-1] == "0.080 mm"
    assert len(set(rb.rows["/error_maps/before/layer_220", "Points3D:colors"][0])) == 9
    assert rb.static["/error_maps/before/layer_220"]
    table = rb.rows["/parameters/fit/table", "TextDocument:text"][0][0]
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
        rec.log_metric("x", "t", 0, 1.0)
        rec.log_text("t", "text")
    rec.close()  # idempotent
    assert list(tmp_path.iterdir()) == []


def test_close_is_idempotent_and_file_readable(tmp_path):
    path = tmp_path / "sub" / "y.rrd"
    rec = Recorder(path, "twice")
    rec.log_metric("m", "t", 0, 1.0)
    rec.close()
    rec.close()
    rec.log_metric("m", "t", 1, 2.0)  # after close: a no-op, not an error
    rb = Readback(path)
    assert rb.times["t"] == {0} and rb.n_blueprints == 0
