"""The hexapod_paper scenario end to end, and the scenario files' error handling."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from recording_faces import assert_every_face_has_data

from calib.data import read_dataset
from scenarios.__main__ import main as cli
from scenarios.config import ScenarioError, load_scenario
from scenarios.runner import run_scenario

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def hexapod_run(tmp_path_factory):
    results = tmp_path_factory.mktemp("results")
    summary, out_dir = run_scenario("hexapod_paper", results, quiet=True)
    return summary, out_dir


def test_the_recording_has_one_face_with_data_in_every_view(hexapod_run):
    """The LM cost is a static figure (log axis), not a second timeline: the verification
    nodes are the one timeline, and every view has data on it."""
    _, out_dir = hexapod_run
    views = {v["name"] for v in assert_every_face_has_data(out_dir / "hexapod_paper.rrd")}
    assert "LM cost by iteration" in views
    for stage in ("before", "after_random_few", "after_random_many"):
        assert any(v.startswith(f"{stage}: errors x") for v in views), stage
        assert any(v.startswith(f"{stage} ≤") for v in views), stage  # its error map


@pytest.mark.accuracy
def test_summary_keys_and_gates(hexapod_run):
    _summary, out_dir = hexapod_run
    on_disk = json.loads((out_dir / "summary.json").read_text())
    assert on_disk["n_parameters"] == 54
    assert on_disk["n_identifiable"] == 54
    # noise-free: the 54 errors of the second paper's Table 2 recovered exactly
    assert on_disk["recovery_noise_free_max_abs_mm"] < 1e-6
    # with noise, more poses recover the parameters better
    assert on_disk["recovery_256_random_max_abs_mm"] < on_disk["recovery_29_random_max_abs_mm"]
    before, after = on_disk["verify_before"], on_disk["verify_after"]
    for key in ("pos_peak_mm", "pos_std_mm", "ori_peak_deg", "ori_std_deg"):
        assert key in before and key in after
    # compensation: the verification error drops by more than an order of magnitude, to the
    # order of the paper's experiment after calibration (Table 6: 0.012 mm, 0.0051 deg)
    assert after["pos_peak_mm"] < before["pos_peak_mm"] / 10
    assert after["pos_peak_mm"] < 0.05
    assert after["ori_peak_deg"] < 0.02
    assert on_disk["n_verification_poses"] == 216
    assert on_disk["runtime_s"] > 0
    assert (out_dir / "report.md").read_text().startswith("# Hexapod")


@pytest.mark.accuracy
def test_recording_holds_the_verification(hexapod_run):
    import rerun.chunk as rerun_chunk

    summary, out_dir = hexapod_run
    store = rerun_chunk.RrdReader(str(out_dir / summary["recording"])).store()
    entities = list(store.schema().entity_paths())
    assert "/error_maps/before/verification_grid/nodes" in entities
    assert "/error_maps/after_random_many/verification_grid/nodes" in entities
    assert "/parameters/random_many" in entities  # the estimates as a table
    assert "/world/targets/before/error" in entities
    times = set()
    for chunk in store.stream():
        batch = chunk.to_record_batch()
        if "verification_node" in batch.schema.names:
            times.update(t for t in batch.column("verification_node").to_pylist() if t is not None)
    assert times == set(range(27))  # one pose per node of the 3 x 3 x 3 grid


@pytest.mark.accuracy
def test_calibration_read_the_dataset_files(hexapod_run):
    _, out_dir = hexapod_run
    ds = read_dataset(out_dir / "datasets" / "random_many.csv", expected_model="hexapod_rrrprr")
    assert ds.n_poses == 256 and ds.n_targets == 3
    assert ds.actuator_names == tuple(f"leg{i}" for i in range(1, 7))


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


def test_unknown_scenario_name():
    with pytest.raises(ScenarioError, match=r"no scenario named 'nope'.*hexapod_paper"):
        load_scenario("nope")


def test_scenario_errors_name_the_cause(tmp_path):
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(str(_write(tmp_path, "name = [")))
    with pytest.raises(ScenarioError, match="missing 'study'"):
        load_scenario(str(_write(tmp_path, 'name = "x"')))
    p = _write(tmp_path, 'name = "x"\nstudy = "nonexistent"')
    with pytest.raises(ScenarioError, match="unknown study 'nonexistent'"):
        run_scenario(str(p), tmp_path, quiet=True)
    text = (
        (ROOT / "scenarios/studies/hexapod_paper/hexapod_paper.toml")
        .read_text()
        .replace('values_file = "truth/', f'values_file = "{ROOT}/scenarios/truth/')
    )
    p = _write(tmp_path, text.replace("seed = 2019", 'seed = "abc"'))
    with pytest.raises(ScenarioError, match="'seed' must be int"):
        run_scenario(str(p), tmp_path, quiet=True)
    missing = text.replace("many_poses = 256\n", "")
    p = _write(tmp_path, missing)
    with pytest.raises(ScenarioError, match=r"missing key 'plans.many_poses'"):
        run_scenario(str(p), tmp_path, quiet=True)
    p = _write(tmp_path, text.replace("hexapod_table2.toml", "no_such_file.toml"))
    with pytest.raises(ScenarioError, match=r"'.*no_such_file.toml' not found"):
        run_scenario(str(p), tmp_path, quiet=True)


def test_cli_reports_scenario_errors(capsys):
    assert cli(["run", "nope"]) == 2
    assert "no scenario named" in capsys.readouterr().err


@pytest.mark.accuracy
def test_other_truth_draws(tmp_path):
    """A seeded random truth (the paper's "errors within +-1 mm") instead of Table 2."""
    text = (ROOT / "scenarios/studies/hexapod_paper/hexapod_paper.toml").read_text()
    text = text.replace('values_file = "truth/hexapod_table2.toml"', "")
    text = text.replace(
        "[pose_noise]",
        '[truth.random]\ndistribution = "uniform"\ntranslation_mm = 1.0\n\n[pose_noise]',
    )
    text = text.replace("seed = 2019", "seed = 4").replace("many_poses = 256", "many_poses = 128")
    path = _write(tmp_path, text)
    s, _ = run_scenario(str(path), tmp_path, quiet=True, record=False)
    assert s["recovery_noise_free_max_abs_mm"] < 1e-6
    after, before = s["verify_after"], s["verify_before"]
    assert after["pos_peak_mm"] < before["pos_peak_mm"] / 10
    assert after["n_unreachable_after_compensation"] < 0.1 * s["n_verification_poses"]
