"""The diagnosis's effect closed through files on the real WAM data (laser tracker, 216 + 20).

diagnose --out, identify --with, verify with default flags exit 0; the reflector sits on J7's
axis in the nominal model, so J7's backlash and eccentricity move it only through the
identified geometry: identify --with starts from the geometric fit and estimates them.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from calib.cli.commands import main

DATA = Path("/work/shared/data/real_wam")
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason="the real WAM data are not here")


def test_wam_loop_through_files(tmp_path, capsys):
    files = ["--model", str(DATA / "real_wam.xml"), "--errors", str(DATA / "real_wam.params.toml")]
    data = [*files, "--data", str(DATA / "real_wam.csv")]
    d, r = tmp_path / "d.json", tmp_path / "r.json"
    cal = [*data, "--set", "calibration"]
    assert main(["diagnose", *cal, "--test-set", "test", "--out", str(d)]) == 0
    diag = json.loads(d.read_text())
    assert diag["diagnosed_effect"] == "backlash+encoder_eccentricity"
    before, reached = diag["test"]["before"]["rms_mm"], diag["test"]["after"]["rms_mm"]
    capsys.readouterr()
    assert main(["identify", *cal, "--with", str(d), "--out", str(r)]) == 0
    said = capsys.readouterr().out
    assert "start: the geometric fit's estimate" in said
    result = json.loads(r.read_text())
    fixed = set((result.get("unidentifiable") or {}).keys())
    assert not {"J7.half_play", "J7.ecc_sin", "J7.ecc_cos"} & fixed
    assert main(["verify", *data, "--result", str(r), "--set", "test"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("after"))
    after = float(line.split("RMS")[1].split("mm")[0])
    # the criterion: at most what the diagnosis reached. Its reported figure is
    # identify --with's fit of its file scored as verify scores it, so the two are equal (to
    # the 4 decimals printed); the linearised fit that ranked the candidates is kept beside it
    # (2.3665 mm against 2.3829 mm delivered: the nonlinear fit of the geometry identify keeps,
    # with the residual correction held)
    assert after <= reached + 0.5e-4 and after < before
    assert diag["test"]["after_fit"] == "identify --with's fit"
    assert diag["test"]["after_linearised"]["rms_mm"] < before
