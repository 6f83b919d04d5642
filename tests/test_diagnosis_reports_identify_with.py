"""What diagnose reports for the effect it names is what identify --with then verify reach.

The diagnosis ranks its candidates by fits linearised at the geometric estimate; the figure
it reports for the named effect comes from the fit identify --with runs on the file it writes
(calib.loop.fit_with_diagnosis), scored by verify's functions on the same test rows. On a
real-like 6R arm in a tracker frame (a registration fitted with the geometry; joints
compliant under a 5 kg payload, 20 calibration + 10 test poses, 0.02 mm tracker), the test
RMS verify prints after identify --with equals the diagnosis's reported one to round-off.
"""

from __future__ import annotations

import json

import pytest

from calib.cli.commands import main
from tests.real_like_cases import arm_case


@pytest.fixture(scope="module")
def arm_loop(tmp_path_factory):
    out = tmp_path_factory.mktemp("arm")
    case = arm_case(out)
    files = ["--model", str(case.model), "--errors", str(case.errors)]
    data = [*files, "--data", str(case.data)]
    cal = [*data, "--set", "calibration"]
    d, r, v = out / "d.json", out / "r.json", out / "v.json"
    assert main(["diagnose", *cal, "--test-set", "test", "--out", str(d)]) == 0
    assert main(["identify", *cal, "--with", str(d), "--out", str(r)]) == 0
    assert main(["verify", *data, "--result", str(r), "--set", "test", "--out", str(v)]) == 0
    return json.loads(d.read_text()), json.loads(v.read_text())


def test_the_diagnosis_reports_what_identify_with_delivers(arm_loop):
    diag, verified = arm_loop
    assert diag["diagnosed_effect"] == "gravity_compliance"
    test = diag["test"]
    assert test["after_fit"] == "identify --with's fit"
    # the same fit of the same file, scored by the same functions: equal to round-off
    for k in ("rms_mm", "mean_mm", "max_mm"):
        assert verified["after"][k] == pytest.approx(test["after"][k], abs=1e-9)
    # the stage table's effect row is that figure too; the ranking fit's is kept beside it
    rows = {r["stage"]: r["rms_mm"] for r in diag["stages"]["rows"]}
    assert rows["effect"] == pytest.approx(test["after"]["rms_mm"], abs=1e-12)
    assert set(test["after_linearised"]) == {"rms_mm", "mean_mm", "max_mm"}
    assert "identify --with's fit: test RMS" in diag["reason"]


def test_without_a_test_set_nothing_is_refitted(tmp_path, capsys):
    case = arm_case(tmp_path)
    files = ["--model", str(case.model), "--errors", str(case.errors), "--data", str(case.data)]
    d = tmp_path / "d.json"
    assert main(["diagnose", *files, "--set", "calibration", "--out", str(d)]) == 0
    assert "identify --with's fit" not in capsys.readouterr().out
    assert "test" not in json.loads(d.read_text())
