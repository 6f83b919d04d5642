"""ISO 9283 pose accuracy and repeatability (``verify --iso9283``) against hand computations.

The attained poses of a small file are the model's own targets at two commands, moved by
offsets chosen so that the standard's formulas give closed forms: at each command four
attained positions offset by (1, 0, 0), (3, 0, 0), (2, 3, 0), (2, 1, 0) mm and the pattern
turned about its own x axis by 0.1, -0.1, 0.3, 0.1 deg (with R = Rz(c) Ry(b) Rx(a), turning
about the tool's own x adds exactly to a). By hand:

* barycentre offset (2, 1, 0) mm: AP_P = sqrt(5) mm, AP_x = 2, AP_y = 1, AP_z = 0;
* distances from the barycentre l_j = sqrt(2), sqrt(2), 2, 0 mm: l_bar = (1 + sqrt(2)) / 2,
  sum (l_j - l_bar)^2 = sum l_j^2 - n l_bar^2 = 8 - (3 + 2 sqrt(2)) = 5 - 2 sqrt(2), so
  S_l = sqrt((5 - 2 sqrt(2)) / 3) and RP_l = l_bar + 3 S_l;
* a: mean 0.1 deg = AP_a; deviations 0, -0.2, 0.2, 0: S_a = sqrt(0.08 / 3), RP_a = 3 S_a;
  b and c unchanged: AP_b = AP_c = 0, RP_b = RP_c = 0.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from calib.analysis.iso9283 import characteristics, group_commands
from calib.cli.commands import main
from calib.data import Dataset, read_dataset, subset, write_dataset
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics import forward_batch
from twin.mechanism import Mechanism
from twin.rigid_fit import fit_rigid_transform
from twin.rotations import matrix_from_rpy

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models/arm6r_3targets.xml"
ERRORS = ROOT / "models/arm6r_3targets.params.toml"
OFFSETS_MM = np.array([[1.0, 0.0, 0.0], [3.0, 0.0, 0.0], [2.0, 3.0, 0.0], [2.0, 1.0, 0.0]])
ROLL_DEG = np.array([0.1, -0.1, 0.3, 0.1])
L_BAR = (1 + math.sqrt(2)) / 2
S_L = math.sqrt((5 - 2 * math.sqrt(2)) / 3)
HAND = {
    "AP_P_mm": math.sqrt(5),
    "AP_x_mm": 2.0,
    "AP_y_mm": 1.0,
    "AP_z_mm": 0.0,
    "l_bar_mm": L_BAR,
    "S_l_mm": S_L,
    "RP_l_mm": L_BAR + 3 * S_L,
    "AP_a_deg": 0.1,
    "AP_b_deg": 0.0,
    "AP_c_deg": 0.0,
    "RP_a_deg": 3 * math.sqrt(0.08 / 3),
    "RP_b_deg": 0.0,
    "RP_c_deg": 0.0,
}


def test_characteristics_follow_the_standard_formulas():
    got = characteristics(OFFSETS_MM * 1e-3, np.zeros(3))
    for key in ("AP_P_mm", "AP_x_mm", "AP_y_mm", "AP_z_mm", "l_bar_mm", "S_l_mm", "RP_l_mm"):
        assert got[key] == pytest.approx(HAND[key], abs=1e-12)
    assert got["n"] == 4 and "AP_a_deg" not in got
    with pytest.raises(ValueError, match="at least 2"):
        characteristics(OFFSETS_MM[:1] * 1e-3, np.zeros(3))


def test_angles_near_180_deg_are_taken_relative_to_the_command():
    yaw = np.array([[0, 0, 179.9], [0, 0, -179.9], [0, 0, 179.9], [0, 0, -179.9]])
    got = characteristics(OFFSETS_MM * 1e-3, np.zeros(3), yaw, np.array([0.0, 0.0, 180.0]))
    # deviations -0.1, +0.1, -0.1, +0.1 deg: mean 0, S = sqrt(0.04 / 3)
    assert got["AP_c_deg"] == pytest.approx(0.0, abs=1e-9)
    assert got["RP_c_deg"] == pytest.approx(3 * math.sqrt(0.04 / 3), abs=1e-9)


def test_identical_commands_group_in_order_of_first_appearance():
    cmds = np.array([[2.0, 0.0], [1.0, 0.0], [2.0, 0.0], [1.0, 1e-12]])
    assert group_commands(cmds).tolist() == [0, 1, 0, 1]


def _small_files(folder: Path) -> tuple[Path, Path, Path]:
    """The same readings twice: the repeat column, and poses with identical commands."""
    mech = Mechanism.from_xml(MODEL)
    lo, hi = mech.actuator_range.T
    commands = np.array([lo + 0.3 * (hi - lo), lo + 0.6 * (hi - lo)])
    targets = forward_batch(mech, commands).targets  # (2, 3, 3)
    local = mech.target_local()
    readings = np.zeros((2, 3, 4, 3))
    for p in range(2):
        rot, _ = fit_rigid_transform(local, targets[p])
        centre = targets[p].mean(axis=0)
        for r in range(4):
            turn = rot @ matrix_from_rpy(np.radians([ROLL_DEG[r], 0, 0])) @ rot.T
            moved = (targets[p] - centre) @ turn.T + centre + OFFSETS_MM[r] * 1e-3
            readings[p, :, r] = moved
    common = {
        "model": mech.name,
        "frame": "base",
        "actuator_names": mech.actuator_names,
        "actuator_units": tuple("mm" if s else "deg" for s in mech.actuator_is_slide),
        "target_names": mech.target_names,
    }
    repeats = Dataset(
        **common,
        pose_ids=np.array([1, 2]),
        sets=np.array(["test", "test"]),
        commands=commands,
        readings=readings,
    )
    flat = Dataset(
        **common,
        pose_ids=np.arange(1, 9),
        sets=np.array(["test"] * 8),
        commands=np.repeat(commands, 4, axis=0),
        readings=np.swapaxes(readings, 1, 2).reshape(8, 3, 1, 3),
    )
    params = load_parameter_set(ERRORS, mech.model)  # the result: every parameter at zero
    result = {
        "format": "pkm-calib-result",
        "version": 1,
        "model": mech.name,
        "frame": "base",
        "parameters": {n: {"value": 0.0, "status": "estimated"} for n in params.names},
    }
    (folder / "result.json").write_text(json.dumps(result))
    return (
        write_dataset(repeats, folder / "repeats.csv"),
        write_dataset(flat, folder / "flat.csv"),
        folder / "result.json",
    )


def test_the_report_of_a_small_file_equals_the_hand_computation(tmp_path, capsys):
    repeats, flat, result = _small_files(tmp_path)
    reports = []
    for data in (repeats, flat):
        out = tmp_path / f"iso_{data.stem}.json"
        args = ["--model", str(MODEL), "--errors", str(ERRORS), "--data", str(data)]
        code = main(["verify", *args, "--result", str(result), "--iso9283", "--out", str(out)])
        assert code == 0
        reports.append(json.loads(out.read_text()))
        rows = list(csv.DictReader(out.with_suffix(".csv").open()))
        assert [(r["pose"], r["side"]) for r in rows] == [
            ("P1", "before"),
            ("P1", "after"),
            ("P2", "before"),
            ("P2", "after"),
        ]
        assert float(rows[0]["RP_l_mm"]) == pytest.approx(HAND["RP_l_mm"], abs=1e-6)
        assert out.with_suffix(".png").read_bytes()[:4] == b"\x89PNG"
    text = capsys.readouterr().out
    assert "P1 (n=4): AP_P 2.2361 -> 2.2361 mm, RP_l 3.7595 -> 3.7595 mm" in text
    for report in reports:
        assert report["n_commanded_poses"] == 2 and report["n_attained_poses"] == 8
        assert report["poses"][0]["pose_ids"] in ([1], [1, 2, 3, 4])
        for pose in report["poses"]:
            for side in ("before", "after"):
                for key, want in HAND.items():
                    # 1e-6 mm / deg: the file's mm are written with 9 decimals (round-trip)
                    assert pose[side][key] == pytest.approx(want, abs=1e-6), (key, side)


def test_readings_without_repeats_are_refused_with_the_reason(tmp_path, capsys):
    _, flat, result = _small_files(tmp_path)
    args = ["--model", str(MODEL), "--errors", str(ERRORS), "--data", str(flat)]
    code = main(["verify", *args, "--result", str(result), "--iso9283", "--set", "nothing"])
    assert code == 2
    one = subset(read_dataset(flat), np.array([True, False, False, False, True] + [False] * 3))
    write_dataset(one, tmp_path / "one.csv")
    args[-1] = str(tmp_path / "one.csv")
    capsys.readouterr()
    assert main(["verify", *args, "--result", str(result), "--iso9283"]) == 2
    assert "no commanded pose is repeated" in capsys.readouterr().err
