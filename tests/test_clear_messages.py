"""Corners that were refused with a misleading message or accepted silently: each now exits
with the cause named (issue points 8 and 9). Twin-made readings of the hexapod (Table 2
truth, 5 um noise) and of the generic 6R arm in a tracker frame 4 m away."""

from __future__ import annotations

import csv
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import scenarios.studies.serial_arm.study as serial_arm
from calib.cli.commands import main
from calib.data import sidecar_path, write_dataset
from calib.fit.verdict import EXIT_BAD_INPUT, EXIT_OK, EXIT_POOR_FIT
from scenarios.config import ScenarioError
from scenarios.runner import run_scenario
from scenarios.twin_datasets import measured_dataset, tracker_frame_dataset
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent
HEX = ("--model", str(ROOT / "models/hexapod_rrrprr.xml"))
HEX_ERRORS = ("--errors", str(ROOT / "models/hexapod_rrrprr.params.toml"))


@pytest.fixture(scope="module")
def hexapod_files(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("messages")
    nominal = Mechanism.from_xml(HEX[1])
    params = load_parameter_set(HEX_ERRORS[1], nominal.model)
    values = load_values(ROOT / "scenarios/truth/hexapod_table2.toml", params)
    truth = Mechanism(params.inject(nominal.model, values), name=nominal.name)
    rng = np.random.default_rng(12)
    poses, commands = random_poses(nominal, 20, rng)
    tracker = Tracker(noise=TrackerNoise("gaussian", 5e-6, 0.0))
    ds = measured_dataset(truth, commands, poses, "calibration", tracker, rng)
    data = write_dataset(ds, tmp / "d.csv")
    one = _first_rows(data, tmp / "one.csv", 3)  # one pose: its three targets
    result = tmp / "r.json"
    assert main(["identify", *HEX, *HEX_ERRORS, "--data", str(data), "--out", str(result)]) == 0
    return {"data": data, "one": one, "result": result, "dir": tmp}


def _first_rows(src: Path, dst: Path, n: int) -> Path:
    rows = list(csv.reader(src.open()))
    with dst.open("w", newline="") as f:
        csv.writer(f).writerows(rows[: n + 1])
    shutil.copy(sidecar_path(src), sidecar_path(dst))
    return dst


def _run(argv: list[str], capsys) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse refuses an argument
        code = int(exc.code)
    out = capsys.readouterr()
    return code, out.out + out.err


def _edited_result(files: dict[str, Path], name: str, value: object) -> Path:
    data = json.loads(files["result"].read_text())
    data["parameters"][name]["value"] = value
    path = files["dir"] / f"edited_{abs(hash(repr(value)))}.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (1e6, "values beyond a plausible size: leg2.base.dx = +1000000.0"),
        ("0.3", "parameter 'leg2.base.dx' has no numeric 'value' (got '0.3' (str)"),
    ],
)
def test_verify_names_the_parameter_of_a_bad_result(hexapod_files, capsys, value, expected):
    result = _edited_result(hexapod_files, "leg2.base.dx", value)
    argv = ["verify", *HEX, *HEX_ERRORS, "--data", str(hexapod_files["data"])]
    code, text = _run([*argv, "--result", str(result)], capsys)
    assert code == EXIT_BAD_INPUT and expected in text and "Traceback" not in text


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--prior-std", "length=1,length=2"], "'length' is given twice"),
        (["--sigma-mm", "1e308"], "1e+308 mm is beyond 100 mm"),
        (["--sigma-mm", "0"], "expected a finite number > 0"),
    ],
)
def test_identify_refuses_an_argument_it_used_to_take(hexapod_files, capsys, extra, expected):
    argv = ["identify", *HEX, *HEX_ERRORS, "--data", str(hexapod_files["data"]), *extra]
    code, text = _run(argv, capsys)
    assert code == EXIT_BAD_INPUT and expected in text
    assert max(len(w) for w in text.split()) < 60  # no 300-digit number


def test_sidecar_accuracy_beyond_reason_is_refused(hexapod_files, capsys, tmp_path):
    data = tmp_path / "d.csv"
    shutil.copy(hexapod_files["data"], data)
    side = json.loads(sidecar_path(hexapod_files["data"]).read_text())
    side["tracker"]["sigma_mm"] = 1e308
    sidecar_path(data).write_text(json.dumps(side))
    code, text = _run(["identify", *HEX, *HEX_ERRORS, "--data", str(data)], capsys)
    assert code == EXIT_BAD_INPUT and "1e+308 mm per coordinate (dataset sidecar)" in text


def test_one_pose_is_not_a_plain_ok(hexapod_files, capsys):
    """Point 9: one pose of three targets gives 9 equations: 6 of the 54 parameters (the
    leg lengths) are identifiable, the residual has 3 degrees of freedom."""
    argv = ["identify", *HEX, *HEX_ERRORS, "--data", str(hexapod_files["one"])]
    code, text = _run([*argv, "--sigma-mm", "0.005"], capsys)
    assert code == EXIT_OK
    verdict = text.strip().splitlines()[-1]
    assert verdict.startswith("weak: only 6 of 54 parameters identifiable from 1 pose")
    assert "(9 equations)" in verdict and "3 degree(s) of freedom" in verdict
    assert "at least 6 give as many equations as unknowns" in verdict


def test_readings_in_metres_in_a_tracker_frame_lead_with_units(tmp_path, capsys):
    """Point 8: on the 6R arm in its tracker's frame a registration and shrunken links can
    follow readings in metres; the failure names the units first, not the estimates."""
    model, errors = ROOT / "models/arm6r.xml", ROOT / "models/arm6r.params.toml"
    nominal = Mechanism.from_xml(model)
    rng = np.random.default_rng(4)
    lo, hi = nominal.actuator_range.T
    commands = rng.uniform(0.8 * lo, 0.8 * hi, (40, nominal.n_actuators))
    tracker = Tracker(position_m=(4.0, 2.0, 0.5), noise=TrackerNoise("gaussian", 1e-5, 0.0))
    ds = tracker_frame_dataset(nominal, tracker, commands, 40, 0.01, rng)
    metres = write_dataset(replace(ds, readings=ds.readings * 1e-3), tmp_path / "m.csv")
    argv = ["identify", "--model", str(model), "--errors", str(errors), "--data", str(metres)]
    code, text = _run(argv, capsys)
    assert code == EXIT_POOR_FIT
    failed = next(line for line in text.splitlines() if line.startswith("FAILED"))
    assert failed.startswith("FAILED: the readings look like metres while the dataset declares")


def test_failed_serial_arm_run_quotes_what_identify_said(tmp_path, monkeypatch):
    """Point 8: the run's folder (and the log in it) is removed on failure, so the error
    carries identify's own words instead of pointing to the deleted log."""

    def refusing(argv):
        print("error: the readings could not be read (a stand-in failure)")
        return 2

    monkeypatch.setattr(serial_arm, "calib_main", refusing)
    with pytest.raises(ScenarioError) as info:
        run_scenario("serial_arm", tmp_path, quiet=True, record=False, figures=False)
    message = str(info.value)
    assert "identify exited 2 without a result" in message
    assert "the readings could not be read (a stand-in failure)" in message
    assert ".log" not in message and not (tmp_path / "serial_arm").exists()
