"""6-DoF probe readings: the quaternion columns, the orientation rows of identification, the
outlier screen, verify's orientation per pose, and what a probe identifies that a reflector
cannot.

The twin's 6R arm carries one target on its tool; a tracker 4.5 m away in its own frame reads
its point (10 um per coordinate) and, as a probe, its frame (0.005 deg per axis; the sidecar
declares both). The truth's errors are drawn on the parameters the probe's readings identify
(the base's, redundant with the tracker's frame, and the two the arm's structure ties, are
zero), so that identify must recover each within its standard error's reach.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib.analysis.identifiability import analyse
from calib.cli.commands import main
from calib.data import Dataset, DatasetError, read_dataset, write_dataset
from calib.fit import calibrate, model_from_files
from calib.fit.probe_rows import ProbeRows, interleave, target_rotations
from calib.fit.registration import project_out, rigid_motion_span
from twin.formats.parameter_file import load_parameter_set
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.probe import probe_orientations
from twin.rotations import matrix_from_quat, matrix_from_rotvec, quat_from_matrix
from twin.tracker import Tracker, TrackerNoise

ROOT = Path(__file__).resolve().parent.parent
ARM, ARM_ERRORS = ROOT / "models/arm6r.xml", ROOT / "models/arm6r.params.toml"
ARM3 = ROOT / "models/arm6r_3targets.xml"
ARM3_ERRORS = ROOT / "models/arm6r_3targets.params.toml"
SIGMA_MM, SIGMA_DEG = 0.01, 0.005
# zero in the truth: the base's (redundant with the tracker's frame) and the two the arm's
# structure ties (link 3's offset with link 2's, the target's z with link 6's offset)
UNSEEN = ("link1.alpha", "link1.a", "link1.d", "link1.theta", "link3.d", "target_1.dz")


def _probe_data(path: Path, n: int = 40, seed: int = 5) -> tuple[Path, np.ndarray]:
    rng = np.random.default_rng(seed)
    nominal = Mechanism.from_xml(ARM)
    params = load_parameter_set(ARM_ERRORS, nominal.model)
    shown = np.where(
        params.is_angle,
        rng.uniform(-0.03, 0.03, len(params)),
        rng.uniform(-0.3, 0.3, len(params)),
    )
    truth_values = params.from_display(shown)
    truth_values[[params.names.index(u) for u in UNSEEN]] = 0.0
    truth = nominal.with_model(params.inject(nominal.model, truth_values))
    lo, hi = nominal.actuator_range.T
    mid, half = (lo + hi) / 2, 0.8 * (hi - lo) / 2
    commands = rng.uniform(mid - half, mid + half, (n, nominal.n_actuators))
    tracker = Tracker(
        (4.0, 2.0, 0.4),
        TrackerNoise.from_spec("gaussian 10 um"),
        rotation_rpy_rad=(0.01, -0.01, 1.7),
    )
    m = measure(truth, commands, tracker, rng)
    quats = probe_orientations(truth, m.true_rotation, tracker, np.radians(SIGMA_DEG), 1, rng)
    ds = Dataset(
        model=nominal.name,
        frame="tracker",
        actuator_names=nominal.actuator_names,
        actuator_units=("deg",) * nominal.n_actuators,
        target_names=nominal.target_names,
        pose_ids=np.arange(1, n + 1),
        sets=np.array(["calibration"] * (n - 10) + ["test"] * 10),
        commands=commands,
        readings=tracker.in_own_frame(m.readings),
        orientations=quats,
        tracker={"sigma_mm": SIGMA_MM, "sigma_deg": SIGMA_DEG},
    )
    return write_dataset(ds, path), truth_values


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    return _probe_data(tmp_path_factory.mktemp("probe") / "probe.csv")


def test_quaternion_columns_round_trip_and_what_is_refused(probe, tmp_path):
    path, _ = probe
    ds = read_dataset(path)
    assert ds.oriented.tolist() == [True]
    text = path.read_text().splitlines()
    assert text[0].endswith("x_mm,y_mm,z_mm,qw,qx,qy,qz")
    again = read_dataset(write_dataset(ds, tmp_path / "again.csv"))
    np.testing.assert_array_equal(again.orientations, ds.orientations)
    sidecar = path.with_name(path.name + ".json").read_text()

    def bad(header: str | None = None, row: tuple[int, str, str] | None = None) -> str:
        lines = list(text)
        if header:
            lines[0] = header
        if row:
            lines[row[0]] = lines[row[0]].replace(row[1], row[2])
        p = tmp_path / "bad.csv"
        p.write_text("\n".join(lines) + "\n")
        p.with_name(p.name + ".json").write_text(sidecar)
        with pytest.raises(DatasetError) as err:
            read_dataset(p)
        return str(err.value)

    for euler in ("rx_deg,ry_deg,rz_deg", "roll,pitch,yaw", "rotvec_x,rotvec_y,rotvec_z"):
        msg = bad(header=text[0].replace("qx,qy,qz", euler).replace(",qw", ""))
        assert "qw,qx,qy,qz" in msg and "Euler" in msg
    assert "missing" in bad(header=text[0].replace(",qz", ",zz"))
    qw = text[1].split(",")[-4]
    assert "no unit quaternion" in bad(row=(1, "," + qw + ",", ",0.5,"))
    assert "at some rows and not at others" in bad(
        row=(1, "," + ",".join(text[1].split(",")[-4:]), ",,,,")
    )


def test_the_orientation_rows_derivatives_match_finite_differences(probe):
    path, _ = probe
    model = model_from_files(str(ARM), str(ARM_ERRORS))
    cmd = read_dataset(path).commands[:6]
    rng = np.random.default_rng(0)
    x = rng.normal(0, 1e-4, model.n_parameters)
    pred = model.predict(x, cmd)
    phi = np.array([0.01, -0.02, 0.015])
    reg_rot = matrix_from_rotvec([0.3, -0.2, 1.0])
    # readings a registration Exp(phi) reg_rot and small errors (1e-3 rad) away from the model
    frames = target_rotations(model.mechanism(x), pred.qpos, np.array([0]))
    small = matrix_from_rotvec(rng.normal(0, 1e-3, (6, 1, 3)))
    rotations = np.swapaxes(matrix_from_rotvec(phi) @ reg_rot, 0, 1) @ small @ frames
    rows = ProbeRows.of(model.nominal, rotations, 1.0)

    def res(xv, rot):
        return rows.residual(model.mechanism(xv), model.predict(xv, cmd).qpos, rot)

    ang = model.tool_twist_jacobian(x, pred.qpos)[:, 3:, :]
    par, reg = rows.jacobian(ang, phi)
    base = res(x, matrix_from_rotvec(phi) @ reg_rot)
    h = 1e-7
    # Gauss-Newton's derivatives are first order in the residual (1e-3 rad): 1e-2 relative
    for j in range(model.n_parameters):
        step = np.zeros(model.n_parameters)
        step[j] = h
        fd = (res(x + step, matrix_from_rotvec(phi) @ reg_rot) - base).reshape(6, -1) / h
        np.testing.assert_allclose(par[:, :, j], fd, atol=1e-2 * max(1.0, np.abs(fd).max()))
    for j in range(3):
        dphi = phi.copy()
        dphi[j] += h
        fd = (res(x, matrix_from_rotvec(dphi) @ reg_rot) - base).reshape(6, -1) / h
        np.testing.assert_allclose(reg[:, :, 3 + j], fd, atol=1e-2)
        assert np.all(reg[:, :, j] == 0)  # the translation leaves an orientation alone


def test_a_probe_identifies_within_the_standard_errors_and_separates_joint_6(probe):
    path, truth = probe
    model = model_from_files(str(ARM), str(ARM_ERRORS))
    ds = read_dataset(path)
    with_probe = calibrate(model, ds, "calibration", regularise=False).result
    est = with_probe.estimated
    z = (with_probe.values - truth)[est] / with_probe.std_errors[est]
    # 21 estimates: |z| < 3.5 for each (a miss has probability 21 * 4.7e-4 = 1 %)
    assert np.abs(z).max() < 3.5
    assert 0.5 < np.sqrt(np.mean(z * z)) < 1.5  # the standard errors are the spread's
    names = dict(zip(with_probe.names, est, strict=True))
    assert names["link6.theta"] and names["target_1.dx"] and names["target_1.dy"]
    plain = calibrate(model, replace(ds, orientations=None), "calibration", regularise=False)
    why = plain.result.report.unidentifiable["link6.theta"]
    assert "one reflector cannot separate a rotation of joint" in why


def test_an_orientation_outlier_is_rejected_and_named(probe, tmp_path):
    path, _ = probe
    ds = read_dataset(path)
    q = np.array(ds.orientations)
    turn = matrix_from_rotvec(np.radians([0.0, 0.0, 1.0]))  # 1 deg: 200 times the noise
    q[3, 0, 0] = quat_from_matrix(turn @ matrix_from_quat(q[3, 0, 0]))
    bad = write_dataset(replace(ds, orientations=q), tmp_path / "outlier.csv")
    out = tmp_path / "r.json"
    args = ["--model", str(ARM), "--errors", str(ARM_ERRORS), "--data", str(bad)]
    assert main(["identify", *args, "--plain", "--out", str(out)]) == 0
    rejected = json.loads(out.read_text())["rejected"]
    assert [(r["pose_id"], r["target"]) for r in rejected] == [(4, "target_1 (orientation)")]


def test_verify_scores_the_probe_orientation_per_pose(probe, tmp_path, capsys):
    path, _ = probe
    args = ["--model", str(ARM), "--errors", str(ARM_ERRORS), "--data", str(path)]
    result, v = tmp_path / "r.json", tmp_path / "v.json"
    assert main(["identify", *args, "--plain", "--out", str(result)]) == 0
    assert main(["verify", *args, "--result", str(result), "--set", "test", "--out", str(v)]) == 0
    scored = json.loads(v.read_text())
    after, before = scored["after"]["orientation"], scored["before"]["orientation"]
    # the angle of a rotation with gaussian components of sigma: RMS sqrt(3) sigma
    assert after["rms_deg"] < 2 * np.sqrt(3) * SIGMA_DEG < before["rms_deg"]
    rows = v.with_suffix(".csv").read_text().splitlines()
    assert rows[0] == "pose_id,target,before_mm,after_mm,before_deg,after_deg"
    assert len(rows) == 11


def _projected(model, commands, weight: float | None) -> np.ndarray:
    """The identification Jacobian (position rows, then with ``weight`` the probe's
    orientation rows) with what the tracker's frame can do projected out."""
    x = np.zeros(model.n_parameters)
    pred = model.predict(x, commands)
    jac, span = model.jacobian(x, pred), rigid_motion_span(pred.targets)
    if weight is not None:
        rows = ProbeRows(np.array([0]), np.eye(3)[None, None].repeat(len(commands), 0), weight)
        ang = model.tool_twist_jacobian(x, pred.qpos)[:, 3:, :]
        jac = interleave(jac, -rows.jacobian(ang, None)[0], len(commands))
        span = interleave(span, rows.registration_span(len(commands)), len(commands))
    return project_out(jac, span) / (SIGMA_MM * 1e-3)  # rows in units of their noise


def test_a_probe_needs_fewer_poses_than_a_reflector_and_no_more_than_three():
    """Side by side on the same random poses (tracker frame): the rank reached and the worst
    standard error of the arm's link angles the three set-ups determine."""
    one = model_from_files(str(ARM), str(ARM_ERRORS))
    three = model_from_files(str(ARM3), str(ARM3_ERRORS))
    rng = np.random.default_rng(2)
    lo, hi = one.nominal.actuator_range.T
    mid, half = (lo + hi) / 2, 0.8 * (hi - lo) / 2
    commands = rng.uniform(mid - half, mid + half, (40, 6))
    weight = SIGMA_MM * 1e-3 / np.radians(SIGMA_DEG)
    setups = {
        "three reflectors": (three, None),
        "one reflector": (one, None),
        "one probe": (one, weight),
    }
    table = {}
    for name, (model, w) in setups.items():
        full = analyse(_projected(model, commands, w), model.params.names)
        ids = [model.params.names.index(n) for n in full.identifiable]
        first_full = next(
            n
            for n in range(2, 41)
            if analyse(_projected(model, commands[:n], w)[:, ids], full.identifiable).rank
            == len(ids)
        )
        angles = [
            i
            for i, n in enumerate(full.identifiable)
            if n.startswith("link") and model.params.is_angle[model.params.names.index(n)]
        ]
        std = {}
        for n in (10, 20, 40):
            jac = _projected(model, commands[:n], w)[:, ids]
            cov = np.linalg.inv(jac.T @ jac)
            std[n] = float(np.degrees(np.sqrt(np.diag(cov)[angles]).max()))
        table[name] = (len(ids), first_full, std)
    _, f3, s3 = table["three reflectors"]
    n1, f1, s1 = table["one reflector"]
    np_, fp, sp = table["one probe"]
    assert np_ == n1 + 1  # joint 6's zero: separated from the target's offset by the probe
    # 6 independent rows per pose against 3: the registration and the parameters need
    # ceil((n + 6) / 6) probe poses, ceil((n + 6) / 3) reflector poses at least
    assert fp == int(np.ceil((np_ + 6) / 6)) and f1 >= int(np.ceil((n1 + 6) / 3)) > fp
    assert fp <= f3
    # the link angles: the probe reads them directly (0.005 deg per pose) where reflectors
    # read them through lever arms of tenths of a metre (10 um / 0.2 m = 0.003 deg)
    assert sp[20] < s3[40] and sp[20] < s1[40]
