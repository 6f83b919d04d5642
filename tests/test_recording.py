"""The rerun recording of a scenario, read back with rerun's own reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scenarios.recording import Recorder
from twin.kinematics import forward, inverse
from twin.mechanism import Mechanism

ROOT = Path(__file__).resolve().parent.parent
rerun_chunk = pytest.importorskip("rerun.chunk")


def _entities_and_times(path: Path) -> tuple[list[str], dict[str, set[int]]]:
    store = rerun_chunk.RrdReader(str(path)).store()
    times: dict[str, set[int]] = {}
    for chunk in store.stream():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.startswith(("pose", "verify_", "lm_iteration", "node")):
                times.setdefault(name, set()).update(batch.column(name).to_pylist())
    return list(store.schema().entity_paths()), times


def test_recording_has_machine_targets_maps_parameters_and_time_points(tmp_path, monkeypatch):
    monkeypatch.setenv("RERUN_STRICT", "1")
    mech = Mechanism.from_xml(ROOT / "models/hexapod_rrrprr.xml")
    path = tmp_path / "x.rrd"
    with Recorder(path, "pkm-calib-test") as rec:
        rec.send_blueprint()
        rec.log_mechanism(mech)
        for i, pose in enumerate(
            [[0, 0, 0.22, 0, 0, 0], [0.01, 0, 0.21, 0.1, 0, 0], [0, 0.01, 0.23, 0, 0.1, 0]]
        ):
            sol = forward(mech, inverse(mech, np.array(pose)).actuators)
            rec.log_pose("pose", i, mech, sol.qpos)
            rec.log_targets("pose", i, sol.targets, sol.targets + 1e-5)
        rec.log_error_map("before", "grid", np.zeros((4, 3)), np.arange(4.0))
        rec.log_parameters("fit", ["a", "b"], np.ones(2), np.ones(2) * 0.1, np.ones(2))
        rec.log_metric("rms", "lm_iteration", 0, 1.0)
    entities, times = _entities_and_times(path)
    for expected in (
        "/world/bodies/platform",
        "/world/targets/measured",
        "/world/targets/error",
        "/error_maps/before/grid",
        "/parameters/fit/estimate",
        "/metrics/rms",
    ):
        assert expected in entities
    assert times["pose"] == {0, 1, 2}


def test_disabled_recorder_does_nothing(tmp_path):
    rec = Recorder(None, "nothing")
    rec.log_mechanism(Mechanism.from_xml(ROOT / "models/hexapod_rrrprr.xml"))
    rec.log_metric("x", "t", 0, 1.0)
    rec.close()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.accuracy
def test_scenario_recording(tmp_path):
    from scenarios.runner import run_scenario

    summary, out_dir = run_scenario("polisher_identifiability", tmp_path, quiet=True)
    entities, times = _entities_and_times(out_dir / summary["recording"])
    assert "/world/bodies/head" in entities and "/identifiability/kept" in entities
    assert any(e.startswith("/metrics/scaled_singular_values") for e in entities)
    assert times["node"] == set(range(summary["n_poses"]))
