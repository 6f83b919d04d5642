"""The residual correction after the physical effects on the real WAM (laser tracker, 216
calibration + 20 test poses): diagnose names backlash + encoder eccentricity and offers the
correction for what they leave; identify --with holds it; verify scores the test poses."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from calib.cli.commands import main

DATA = Path("/work/shared/data/real_wam")
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason="the real WAM data are not here")


def test_wam_correction_after_the_effects(tmp_path, capsys):
    files = ["--model", str(DATA / "real_wam.xml"), "--errors", str(DATA / "real_wam.params.toml")]
    data = [*files, "--data", str(DATA / "real_wam.csv")]
    cal = [*data, "--set", "calibration"]
    d, r, v = tmp_path / "d.json", tmp_path / "r.json", tmp_path / "v.json"
    assert main(["diagnose", *cal, "--test-set", "test", "--out", str(d)]) == 0
    diag = json.loads(d.read_text())
    assert diag["diagnosed_effect"] == "backlash+encoder_eccentricity"
    assert diag["residual_correction_verdict"].startswith("offered")
    rows = {r["stage"]: r for r in diag["stages"]["rows"]}
    assert all(rows[s]["share_percent"] > 0 for s in ("geometry", "effect", "correction"))
    assert rows["correction"]["rms_mm"] < rows["effect"]["rms_mm"] < rows["geometry"]["rms_mm"]
    assert Path(diag["stages"]["figure"]).is_file()
    assert main(["identify", *cal, "--with", str(d), "--out", str(r)]) == 0
    assert "residual_correction" in json.loads(r.read_text())
    capsys.readouterr()
    assert main(["verify", *data, "--result", str(r), "--set", "test", "--out", str(v)]) == 0
    said = capsys.readouterr().out
    line = next(x for x in said.splitlines() if x.startswith("with the residual correction"))
    rms, top = (
        float(x) for x in re.search(r"RMS ([0-9.]+) mm.*max ([0-9.]+) mm \(", line).groups()
    )
    without = json.loads(v.read_text())["after"]
    # the criterion: lower test RMS than the effects alone, the maximum not raised
    assert rms < without["rms_mm"] and top <= without["max_mm"]
    assert rms < diag["test"]["after"]["rms_mm"]
    assert "0 of 20 pose(s) outside the calibrated region" in said
