"""Before readings are rejected as gross outliers, identify tries the error model's fuller
variant (the base's placement, for readings in the base frame) and keeps it when it explains
them; the generated error models hold the base's placement by default."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib.cli.commands import main
from calib.data import read_dataset, write_dataset
from calib.fit import EXIT_OK, calibrate, model_from_files
from calib.fit.fuller_model import explained, holds_rigid_motion
from calib.fit.model import CalibrationModel
from calib.fit.robust import Rejection
from scenarios.twin_datasets import measured_dataset
from twin.formats.dh_mjcf import build_parameters, build_xml
from twin.formats.dh_table import parse_dh_table
from twin.formats.error_model import error_parameters
from twin.formats.from_urdf import convert
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise

ROOT = Path(__file__).resolve().parent.parent
# a UR5's published standard-DH table (ros-industrial ur_kinematics), reflector on the flange
TABLE = """# convention: standard
joint,alpha_deg,a_mm,d_mm,theta_deg,min_deg,max_deg
J1,90,0,89.159,0,-360,360
J2,0,-425,0,0,-360,360
J3,0,-392.25,0,0,-360,360
J4,90,0,109.15,0,-360,360
J5,-90,0,94.65,0,-360,360
J6,0,0,82.3,0,-360,360
site,x_mm,y_mm,z_mm
tool,0,0,31
target_1,0,0,31
"""
SIGMA_MM = 0.015
HOME = np.array([0.0, -1.2, 1.3, -1.6, -1.5, 0.0])


def _arm(tmp: Path) -> tuple[Path, Path, Path, Mechanism]:
    """The arm's model, its error model without and with the base's placement."""
    table = parse_dh_table(TABLE)
    (tmp / "ur.xml").write_text(build_xml(table, "ur"))
    (tmp / "small.params.toml").write_text(build_parameters(table, "ur", base_errors=False))
    (tmp / "full.params.toml").write_text(build_parameters(table, "ur"))
    nominal = Mechanism.from_xml(tmp / "ur.xml")
    return tmp / "ur.xml", tmp / "small.params.toml", tmp / "full.params.toml", nominal


def _base_frame_data(tmp: Path, tilt_deg: float, outlier_mm: float = 0.0) -> tuple[Path, ...]:
    """Readings in the base frame of an arm whose base is tilted by ``tilt_deg`` and shifted
    (neither for 0), besides DH errors of a built arm: 200 poses near one configuration and
    6 with the first joint turned far from it (where a base tilt shows most), then 20 test
    poses near it; ``outlier_mm`` moves the 10th reading that far (a gross error)."""
    xml, small, full, nominal = _arm(tmp)
    params = load_parameter_set(full, nominal.model)
    rng = np.random.default_rng(2)
    shown = np.where(
        params.is_angle,
        rng.uniform(-0.05, 0.05, len(params)),
        rng.uniform(-0.3, 0.3, len(params)),
    )
    for k, name in enumerate(params.names):
        if name.startswith("base.r"):
            shown[k] = tilt_deg * {"x": 1.0, "y": -0.7, "z": 0.3}[name[-1]]
        elif name.startswith("base.") and tilt_deg == 0:  # no placement error at all
            shown[k] = 0.0
    truth = nominal.with_model(params.inject(nominal.model, params.from_display(shown)))
    far = HOME + rng.uniform(-0.35, 0.35, (6, 6))
    far[:, 0] += np.linspace(1.5, 3.0, 6)
    near = HOME + rng.uniform(-0.35, 0.35, (220, 6))
    commands = np.vstack([far, near])
    tracker = Tracker(position_m=(2.0, 1.0, 0.5), noise=TrackerNoise.from_spec("gaussian 15 um"))
    ds = measured_dataset(truth, commands, commands, "calibration", tracker, rng)
    sets = ds.sets.copy()
    sets[-20:] = "test"
    readings = ds.readings.copy()
    readings[10, 0, ..., 0] += outlier_mm * 1e-3
    ds = replace(ds, sets=sets, readings=readings, tracker={**ds.tracker, "sigma_mm": SIGMA_MM})
    return xml, small, full, write_dataset(ds, tmp / "ur.csv")


def test_generated_error_models_hold_the_base_placement(tmp_path):
    """The DH generator's default and the URDF generator's complete model can move the
    machine rigidly; a DH model made with --no-base-errors cannot."""
    xml, small, full, _ = _arm(tmp_path)
    q = HOME + np.random.default_rng(0).uniform(-1, 1, (30, 6))
    for errors, holds in ((small, False), (full, True)):
        model = model_from_files(str(xml), str(errors))
        assert holds_rigid_motion(model, np.zeros(model.n_parameters), q) is holds
    _, _, urdf = convert(
        ROOT / "models" / "arm6r.urdf", ["target_1=link6@0,40,110"], None, "arm6r_urdf"
    )
    model = CalibrationModel(urdf, error_parameters(urdf))
    lo, hi = urdf.actuator_range.T
    q = np.random.default_rng(1).uniform(0.8 * lo + 0.2 * hi, 0.2 * lo + 0.8 * hi, (30, 6))
    assert holds_rigid_motion(model, np.zeros(model.n_parameters), q)


def test_explained_keeps_the_fuller_model_only_when_it_keeps_readings():
    a, b, c = Rejection(0, 0, 1.0), Rejection(1, 0, 1.0), Rejection(2, 0, 1.0)
    assert explained((a, b), ()) == (a, b)
    assert explained((a, b), (b,)) == (a,)
    assert explained((a, b), (a, b)) is None  # nothing explained
    assert explained((a,), (b,)) is None  # as many rejected, only other ones
    assert explained((a, b), (a, c)) is None


def test_readings_a_base_tilt_explains_are_kept(tmp_path, capsys):
    xml, small, _, data = _base_frame_data(tmp_path, tilt_deg=0.05)
    files = ["--model", str(xml), "--errors", str(small), "--data", str(data)]
    out = tmp_path / "r.json"
    assert main(["identify", *files, "--set", "calibration", "--out", str(out)]) == EXIT_OK
    text = capsys.readouterr().out
    r = json.loads(out.read_text())
    assert r["rejected"] == []
    fuller = r["fuller_model"]
    assert fuller["added"] == [f"base.{a}{c}" for a in "dr" for c in "xyz"]
    assert fuller["rejected_before"] >= 1 and fuller["rejected_after"] == 0
    kept = fuller["kept_readings"]
    assert len(kept) == fuller["rejected_before"]
    # the readings kept are the far poses (pose ids 0-5), above the smaller fit's limit
    assert {k["pose_id"] for k in kept} <= set(range(6))
    assert all(k["residual_mm"] > fuller["rejection_limit_before_mm"] for k in kept)
    assert fuller["text"] in text and f"{len(kept)} of the" in fuller["text"]
    assert [p["name"] for p in r["added_parameters"]] == fuller["added"]
    v = tmp_path / "v.json"
    assert main(["verify", *files, "--result", str(out), "--set", "test", "--out", str(v)]) == 0
    after = json.loads(v.read_text())["after"]["rms_mm"]
    # the truth is inside the fuller model: noise of sqrt(3) x 0.015 = 0.026 mm (3D RMS)
    # plus estimation error remain; twice that bounds the held-out error
    assert after < 2 * np.sqrt(3) * SIGMA_MM


@pytest.mark.parametrize("tilt_deg", [0.0, 0.05])
def test_a_gross_error_stays_rejected(tmp_path, tilt_deg):
    """A reading moved 3 mm is rejected whatever the model; with a base tilt in the truth the
    fuller model is kept for the far poses, the gross error still rejected by it."""
    xml, small, _, data = _base_frame_data(tmp_path, tilt_deg=tilt_deg, outlier_mm=3.0)
    model = model_from_files(str(xml), str(small))
    run = calibrate(model, read_dataset(data), "calibration", sigma_mm=SIGMA_MM)
    assert [(r.pose_index, r.target_index) for r in run.result.rejected] == [(10, 0)]
    if tilt_deg == 0.0:
        assert run.fuller is None and "base.dx" not in run.model.params.names
    else:
        assert run.fuller is not None and run.fuller.rejected_after == 1
