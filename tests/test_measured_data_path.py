"""The measured-data path, as a user takes it, on the serial_arm scenario and on bad input.

A serial MJCF with no loop and no masses, an MDH error model and a tracker-frame dataset
with a set column go through `identify --set calibration` and `verify --set test` (the
scenario runs those commands in process); and each bad input a user meets ends with a clear
error naming the cause.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calib.cli.commands import main
from calib.data import read_dataset, write_dataset
from calib.data.result_file import load_result
from calib.data.select import subset
from scenarios.runner import run_scenario

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "models/arm6r.xml"
ARM_ERRORS = ROOT / "models/arm6r.params.toml"


@pytest.fixture(scope="module")
def arm_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("results")
    summary, out = run_scenario("serial_arm", results_root=root, quiet=True, record=False)
    return summary, out


@pytest.mark.accuracy
def test_serial_arm_identifies_and_verifies_on_held_out_poses(arm_run):
    s, _ = arm_run
    for v in (s, s["variants"]["three_reflectors"]):
        assert v["exit_codes"] == {"identify": 0, "verify": 0}
        before, after = v["test"]["before"]["rms_mm"], v["test"]["after"]["rms_mm"]
        # DH errors of 0.3 mm / 0.03-0.05 deg: about 0.7-1 mm before; after, the tracker
        # noise (3D RMS 0.043 mm at 4.5 m) is what remains
        assert before > 0.3
        assert after < 0.06 and after < 0.1 * before
        assert v["calibration"]["rms_mm"] < 1.2 * v["noise_floor_3d_mm"]
        assert set(v["redundant_with_registration"]) == {
            "link1.alpha",
            "link1.a",
            "link1.d",
            "link1.theta",
        }
        assert v["masses_defaulted"] is True
        assert v["registration_error_mm"] < 2.0  # the absorbed link-1 errors, see report
    assert s["n_identifiable"] == 20 and s["variants"]["three_reflectors"]["n_identifiable"] == 26
    ori = s["variants"]["three_reflectors"]["test"]
    assert ori["after"]["orientation"]["rms_deg"] < 0.3 * ori["before"]["orientation"]["rms_deg"]
    for key in ("test", "registration_error_mm", "n_identifiable"):
        assert key in s
    assert {"rms_mm", "mean_mm", "max_mm"} <= set(s["test"]["after"])


def test_result_file_loads_back_with_units_registration_and_status(arm_run):
    _, out = arm_run
    path = out / "one_reflector_result.json"
    assert (path.stat().st_mode & 0o777) == 0o644
    loaded = load_result(path, expected_model="arm6r")
    data = loaded.data
    assert data["units"] == {"length": "mm", "angle": "deg"}
    assert data["frame"] == "tracker" and loaded.registration is not None
    reg = data["registration"]
    assert 4000 < reg["distance_mm"] < 5000 and len(reg["std_translation_mm"]) == 3
    fixed = {n: p for n, p in data["parameters"].items() if p["status"] == "fixed"}
    assert "registration" in fixed["link1.theta"]["reason"]
    assert all(
        p["std"] is not None for p in data["parameters"].values() if p["status"] == "estimated"
    )
    assert data["selection"].startswith("40 of 60 poses (set 'calibration')")
    assert "metric" in data and data["residual"]["n"] == 40


def test_verify_writes_json_csv_and_png(arm_run, tmp_path, capsys):
    _, out = arm_run
    data = out / "datasets/one_reflector.csv"
    v = tmp_path / "v.json"
    args = ["verify", "--model", str(ARM), "--errors", str(ARM_ERRORS), "--data", str(data)]
    assert (
        main(
            [
                *args,
                "--result",
                str(out / "one_reflector_result.json"),
                "--set",
                "test",
                "--out",
                str(v),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "20 of 60 poses (set 'test')" in text and "3D position error per reading" in text
    result = json.loads(v.read_text())
    assert result["n_poses"] == 20
    for side in ("before", "after"):
        assert {"rms_mm", "mean_mm", "max_mm"} <= set(result[side])
    rows = v.with_suffix(".csv").read_text().splitlines()
    assert rows[0] == "pose_id,target,before_mm,after_mm" and len(rows) == 21
    assert v.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _args(data: Path, *extra: str) -> list[str]:
    return ["--model", str(ARM), "--errors", str(ARM_ERRORS), "--data", str(data), *extra]


def test_an_empty_set_is_named(arm_run, capsys):
    _, out = arm_run
    code = main(["identify", *_args(out / "datasets/one_reflector.csv", "--set", "tset")])
    assert code == 2
    assert "no pose in set 'tset'" in capsys.readouterr().err


def test_a_result_file_from_another_model_is_refused(arm_run, tmp_path, capsys):
    _, out = arm_run
    other = json.loads((out / "one_reflector_result.json").read_text())
    other["model"] = "hexapod_rrrprr"
    bad = tmp_path / "other.json"
    bad.write_text(json.dumps(other))
    code = main(["verify", *_args(out / "datasets/one_reflector.csv", "--result", str(bad))])
    assert code == 2
    assert "result for model 'hexapod_rrrprr', not for 'arm6r'" in capsys.readouterr().err


def test_a_registration_that_cannot_be_found_is_named(arm_run, tmp_path, capsys):
    """One pose repeated: the readings coincide, no frame can be fitted to them."""
    _, out = arm_run
    ds = read_dataset(out / "datasets/one_reflector.csv")
    one = subset(ds, np.arange(ds.n_poses) < 1)
    same = type(one)(
        **{
            **one.__dict__,
            "pose_ids": np.arange(30),
            "sets": np.array(["calibration"] * 30),
            "commands": np.repeat(one.commands, 30, axis=0),
            "readings": np.repeat(one.readings, 30, axis=0),
            "order": np.arange(30),
        }
    )
    path = write_dataset(same, tmp_path / "same.csv")
    code = main(["identify", *_args(path)])
    assert code == 2
    assert "tracker's frame" in capsys.readouterr().err


def test_non_convergence_exits_3_and_says_which_criterion(arm_run, capsys):
    _, out = arm_run
    code = main(["identify", *_args(out / "datasets/one_reflector.csv", "--max-iterations", "1")])
    assert code == 3
    assert "did not converge (iteration limit)" in capsys.readouterr().err


def test_diagnosis_loads_only_a_payload_on_defaulted_masses_in_the_tracker_frame(
    arm_run, tmp_path, capsys
):
    _, out = arm_run
    d = tmp_path / "d.json"
    data = out / "datasets/one_reflector.csv"
    assert main(["diagnose", *_args(data, "--sigma-mm", "0.021", "--out", str(d))]) == 0
    result = json.loads(d.read_text())
    # the model declares no masses: its own weight is not invented, gravity is tried only as
    # a tool payload whose mass and the compliances are fitted as products
    assert "gravity_compliance" in result["candidates"]
    assert any("tool payload only" in n and "no masses" in n for n in result["notes"])
    # registered into the base frame, the residual is the tracker noise: nothing invented
    assert result["diagnosed_effect"] == "none"
