"""Coming back another day with the tracker moved: ``verify --register`` and the refusal
without it.

The twin's arm (three reflectors, DH errors, joints that wind up under a payload, which the
geometric error model cannot hold) is measured on the calibration day from one tracker
station (calibration and held-out test poses) and on the test day from another, metres away
and turned by any angle, at the held-out poses again. The tracker is noise-free, so that the
test day's readings are exactly a rigid motion of the held-out ones: registered afresh they
must score what the held-out poses score registered afresh (to rounding), and no more than
the held-out poses under the result's own registration, because the closed-form rigid fit
is the least-squares optimum over every rigid motion, that one included.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib.cli.commands import main
from calib.data import read_dataset, write_dataset
from calib.fit import model_from_files, verify_registered
from scenarios.twin_datasets import tracker_frame_dataset
from twin.effects import JointCompliance
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rpy
from twin.tracker import Tracker, TrackerNoise

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models/arm6r_3targets.xml"
ERRORS = ROOT / "models/arm6r_3targets.params.toml"
N_CAL, N_TEST = 40, 12


@pytest.fixture(scope="module")
def days(tmp_path_factory):
    out = tmp_path_factory.mktemp("days")
    rng = np.random.default_rng(34)
    nominal = Mechanism.from_xml(MODEL)
    params = load_parameter_set(ERRORS, nominal.model)
    shown = np.where(
        params.is_angle,
        rng.uniform(-0.03, 0.03, len(params)),
        rng.uniform(-0.3, 0.3, len(params)),
    )
    truth = nominal.with_model(params.inject(nominal.model, params.from_display(shown)))
    lo, hi = nominal.actuator_range.T
    mid, half = (lo + hi) / 2, 0.8 * (hi - lo) / 2
    commands = rng.uniform(mid - half, mid + half, (N_CAL + N_TEST, nominal.n_actuators))
    effects = [JointCompliance(stiffness_Nm_per_rad=5e4, payload_kg=5.0)]
    noise = TrackerNoise.none()
    day1 = Tracker((4.0, 2.0, 0.4), noise, rotation_rpy_rad=_rad(0.4, -0.7, 100.0))
    day2 = Tracker((-2.5, 5.5, 1.7), noise, rotation_rpy_rad=_rad(20.0, 35.0, -140.0))
    ds1 = tracker_frame_dataset(truth, day1, commands, N_CAL, 0.01, rng, effects)
    ds2 = tracker_frame_dataset(truth, day2, commands[N_CAL:], 0, 0.01, rng, effects)
    paths = {"day1": out / "day1.csv", "day2": out / "day2.csv"}
    write_dataset(ds1, paths["day1"])
    write_dataset(ds2, paths["day2"])
    paths["result"] = out / "result.json"
    assert main(["identify", *_args(paths["day1"]), "--out", str(paths["result"])]) == 0
    return paths


def _args(data: Path) -> list[str]:
    return ["--model", str(MODEL), "--errors", str(ERRORS), "--data", str(data)]


def _verify(capsys, days, data: Path, out: Path, *extra: str) -> tuple[int, dict | None, str]:
    code = main(
        ["verify", *_args(data), "--result", str(days["result"]), "--out", str(out), *extra]
    )
    err = capsys.readouterr().err
    return code, (json.loads(out.read_text()) if out.exists() else None), err


def test_the_test_day_registered_afresh_scores_as_the_held_out_poses(days, tmp_path, capsys):
    code, held_out, _ = _verify(capsys, days, days["day1"], tmp_path / "h.json", "--set", "test")
    assert code == 0
    code, again, _ = _verify(
        capsys, days, days["day1"], tmp_path / "a.json", "--set", "test", "--register"
    )
    assert code == 0
    code, other_day, _ = _verify(capsys, days, days["day2"], tmp_path / "d.json", "--register")
    assert code == 0 and "registered afresh (--register)" in other_day["note"]
    assert other_day["n_poses"] == N_TEST
    for side in ("before", "after"):
        # the test day's readings are a rigid motion of the held-out ones: same scores
        assert other_day[side]["rms_mm"] == pytest.approx(again[side]["rms_mm"], abs=1e-6)
        assert other_day[side]["max_mm"] == pytest.approx(again[side]["max_mm"], abs=1e-6)
    # the least-squares rigid fit does no worse than the result's own registration
    assert other_day["after"]["rms_mm"] <= held_out["after"]["rms_mm"] + 1e-9
    # and it does not hide the compliance the error model cannot hold (tens of micrometres)
    assert other_day["after"]["rms_mm"] > 0.01 > 1e-3
    assert other_day["after"]["rms_mm"] < other_day["before"]["rms_mm"]
    # the orientation of three reflectors is scored alike
    assert other_day["after"]["orientation"]["rms_deg"] == pytest.approx(
        again["after"]["orientation"]["rms_deg"], abs=1e-7
    )


def test_plain_verify_of_another_station_exits_4_with_the_advice(days, tmp_path, capsys):
    out = tmp_path / "v.json"
    code, written, err = _verify(capsys, days, days["day2"], out)
    assert code == 4 and written is None and not out.exists()
    assert "look like another tracker station" in err and "--register" in err
    residual = json.loads(days["result"].read_text())["residual_rms_mm"]
    assert f"({residual:.4f} mm)" in err


def test_register_set_fits_on_its_rows_and_scores_the_others(days, tmp_path, capsys):
    ds = read_dataset(days["day2"])
    sets = np.array(["register"] * 5 + ["test"] * (N_TEST - 5))
    path = tmp_path / "day2_sets.csv"
    write_dataset(replace(ds, sets=sets), path)
    out = tmp_path / "v.json"
    code = main(
        [
            "verify",
            *_args(path),
            "--result",
            str(days["result"]),
            "--register-set",
            "register",
            "--out",
            str(out),
        ]
    )
    text = capsys.readouterr().out
    assert code == 0 and "7 of 12 poses scored, registered on the 5 poses of set 'register'" in text
    assert json.loads(out.read_text())["n_poses"] == N_TEST - 5
    bad = main(["verify", *_args(path), "--result", str(days["result"]), "--register-set", "x"])
    assert bad == 2 and "no pose in that set" in capsys.readouterr().err


def test_scores_registered_afresh_do_not_depend_on_the_tracker_frame():
    model = model_from_files(str(MODEL), str(ERRORS))
    rng = np.random.default_rng(1)
    lo, hi = model.nominal.actuator_range.T
    commands = rng.uniform(lo * 0.5, hi * 0.5, (15, model.nominal.n_actuators))
    values = rng.normal(0.0, 1e-4, model.n_parameters)
    truth = model.predict(values, commands).targets + rng.normal(0, 1e-4, (15, 3, 3))
    rot = matrix_from_rpy(np.radians([30.0, -60.0, 170.0]))
    moved = truth @ rot.T + np.array([3.0, -4.0, 2.0])
    ids = np.arange(15)
    a = verify_registered(model, values, commands, truth, ids)
    b = verify_registered(model, values, commands, moved, ids)
    for side in ("before", "after"):
        np.testing.assert_allclose(
            getattr(a, side).per_reading_m, getattr(b, side).per_reading_m, atol=1e-12
        )
    # the calibrated side fits its own model's points: only the added noise is left
    assert a.after.position.rms_mm < a.before.position.rms_mm


def _rad(*deg: float) -> tuple[float, ...]:
    return tuple(float(v) for v in np.radians(deg))
