"""serial_arm after verify: compensate, the truth twin re-measured, export; and the generated
error model (from the MJCF and from the arm's URDF) against the hand-written one on the
scenario's own data.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from to_machine_support import MODELS

from calib.cli.commands import main as calib_main
from scenarios.runner import run_scenario
from twin.formats.error_model import main as error_model_main
from twin.formats.from_urdf import main as from_urdf_main


@pytest.fixture(scope="module")
def arm_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("results")
    return run_scenario("serial_arm", results_root=root, quiet=True, record=False)


@pytest.mark.accuracy
def test_compensation_through_the_commands_lowers_the_true_error(arm_run):
    s, out = arm_run
    one, three = s, s["variants"]["three_reflectors"]
    for v in (one, three):
        c, e = v["compensation"], v["export"]
        assert c["exit_code"] == 0 and c["n_compared"] == c["n_desired"] == 20
        assert e["exit_codes"] == {"export": 0, "verify_as_is": 0}
        assert c["before"]["rms_mm"] > 0.3  # DH errors of 0.3 mm / 0.03-0.05 deg
        # what compensation leaves is one offset the tool carries (the tool point no reflector
        # sees: reflector and flange offsets along joint 6 act alike) plus noise-sized scatter
        assert c["after_spread_about_it_mm"] < 0.03
        assert e["max_fk_diff_mm"] < 1e-6 and e["dh_table_max_fk_diff_mm"] < 1e-6
        # the exported model, scored as it is, predicts the test set as the result did
        assert e["verify_as_is_test"]["rms_mm"] == pytest.approx(
            v["test"]["after"]["rms_mm"], rel=0.05
        )
        # which of the two takes the offset is the fit's choice (the smaller estimates): the
        # tool point then misses by a reflector's or the flange's offset, of the truth's size
        assert c["after"]["rms_mm"] < 0.5 * c["before"]["rms_mm"]
    for name in (
        "one_reflector_commands.csv",
        "one_reflector_calibrated.xml",
        "one_reflector_calibrated.mdh.csv",
    ):
        assert (out / name).is_file()
    assert "## From the calibration to the machine" in (out / "report.md").read_text()


def _held_out(tmp_path, model, errors, data, tag) -> float:
    result, verify = tmp_path / f"{tag}_r.json", tmp_path / f"{tag}_v.json"
    common = ["--model", str(model), "--errors", str(errors), "--data", str(data)]
    assert calib_main(["identify", *common, "--set", "calibration", "--out", str(result)]) == 0
    assert (
        calib_main(
            ["verify", *common, "--result", str(result), "--set", "test", "--out", str(verify)]
        )
        == 0
    )
    return json.loads(verify.read_text())["after"]["rms_mm"]


@pytest.mark.accuracy
def test_generated_error_models_identify_the_same_held_out_accuracy(arm_run, tmp_path):
    s, out = arm_run
    data = out / "datasets" / "one_reflector.csv"
    hand = s["test"]["after"]["rms_mm"]
    generated = tmp_path / "arm6r.generated.toml"
    assert error_model_main([str(MODELS / "arm6r.xml"), "--out", str(generated)]) == 0
    from_mjcf = _held_out(tmp_path, MODELS / "arm6r.xml", generated, data, "mjcf")
    urdf_dir = tmp_path / "urdf"
    args = ["--target", "target_1=link6@50,0,110", "--tool", "link6@0,0,120"]
    assert from_urdf_main([str(MODELS / "arm6r.urdf"), *args, "--out-dir", str(urdf_dir)]) == 0
    from_urdf = _held_out(
        tmp_path, urdf_dir / "arm6r.xml", urdf_dir / "arm6r.params.toml", data, "urdf"
    )
    # 39 generated parameters against 27 hand-written ones: the same held-out error to a few
    # per cent (a little more noise fitted), and the URDF's model gives the very same fit
    assert from_mjcf == pytest.approx(hand, rel=0.1)
    assert from_urdf == pytest.approx(from_mjcf, rel=1e-6)


def test_logs_and_summary_name_the_final_folder(arm_run):
    """The commands logged during the run name the files where they are after the swap: no
    path into the run's ``.serial_arm.partial-*`` folder (gone by then), and every file a
    logged command wrote (--out) is there."""
    _, out = arm_run
    logs = sorted(out.glob("*.log"))
    assert len(logs) >= 8  # identify, verify, compensate, export, ... of both variants
    outs = []
    for log in logs:
        text = log.read_text()
        assert ".partial-" not in text, log.name
        words = text.splitlines()[0].split()
        outs += [words[i + 1] for i, w in enumerate(words[:-1]) if w == "--out"]
    assert outs and all(Path(p).exists() for p in outs), outs
    assert all(Path(p).parent == out for p in outs if "datasets" not in p)
    # and the files the command line wrote (results, verify reports) name their inputs so too
    for written in [*out.rglob("*.json"), *out.rglob("*.md")]:
        assert ".partial-" not in written.read_text(), written.name
    result = json.loads((out / "one_reflector_result.json").read_text())
    named = [v for v in json.dumps(result).split('"') if v.endswith("one_reflector.csv")]
    assert named and all(Path(v).is_file() for v in named), named
