"""The command a user runs on a real machine's readings: python -m calib identify."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from calib.cli.commands import main
from calib.data import write_dataset
from scenarios.twin_datasets import measured_dataset
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models/hexapod_rrrprr.xml"
ERRORS = ROOT / "models/hexapod_rrrprr.params.toml"


def test_identify_from_files_recovers_the_truth(tmp_path, capsys):
    nominal = Mechanism.from_xml(MODEL)
    params = load_parameter_set(ERRORS, nominal.model)
    truth_values = load_values(ROOT / "scenarios/truth/hexapod_table2.toml", params)
    truth = Mechanism(params.inject(nominal.model, truth_values), name=nominal.name)
    rng = np.random.default_rng(11)
    poses, commands = random_poses(nominal, 12, rng)
    tracker = Tracker(noise=TrackerNoise.none())
    ds = measured_dataset(truth, commands, poses, "calibration", tracker, rng)
    csv = write_dataset(ds, tmp_path / "readings.csv")
    out = tmp_path / "result.json"
    code = main(
        [
            "identify",
            "--model",
            str(MODEL),
            "--errors",
            str(ERRORS),
            "--data",
            str(csv),
            "--out",
            str(out),
        ]
    )
    assert code == 0
    assert "54 of 54 parameters identifiable" in capsys.readouterr().out
    result = json.loads(out.read_text())
    shown = params.to_display(truth_values)
    for name, t in zip(params.names, shown, strict=True):
        assert abs(result["parameters"][name]["value"] - t) < 1e-6
    assert result["residual_rms_mm"] < 1e-9


def test_identify_reports_bad_input(tmp_path, capsys):
    code = main(
        [
            "identify",
            "--model",
            str(MODEL),
            "--errors",
            str(ERRORS),
            "--data",
            str(tmp_path / "missing.csv"),
        ]
    )
    assert code == 2
    assert "dataset CSV file not found" in capsys.readouterr().err
    code = main(
        [
            "identify",
            "--model",
            str(tmp_path / "none.xml"),
            "--errors",
            str(ERRORS),
            "--data",
            str(tmp_path / "missing.csv"),
        ]
    )
    assert code == 2
    assert "MJCF file not found" in capsys.readouterr().err
