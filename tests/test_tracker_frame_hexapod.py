"""Hexapod readings in a tracker frame 200-4500 mm away or turned 180 degrees converge within
the default iterations, to the same parameters whatever the frame, and predict held-out
poses as well as the fit of the same readings in the base frame (the registration turns
about the readings' centre; a nearly redundant base tilt leaves a curved valley that
geodesic acceleration follows). Also the acceleration on Rosenbrock's valley, whose exact
minimum is known."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.cli.commands import main
from calib.data import Dataset, write_dataset
from calib.estimators.levenberg_marquardt import LMOptions, levenberg_marquardt
from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations
from calib.fit.registration import Registration, about, about_jacobian, identity
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rotvec
from twin.tracker import Tracker
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models/hexapod_rrrprr.xml"
ERRORS = ROOT / "models/hexapod_rrrprr.params.toml"
FRAMES = {  # tracker origin (mm) and turn about z (deg); a small tilt on top of each
    "200 mm": ((200.0, 60.0, -40.0), 0.0),
    "4500 mm": ((4500.0, 1350.0, -900.0), 0.0),
    "turned 180 deg": ((0.0, 0.0, 0.0), 180.0),
    "4500 mm, 180 deg": ((4500.0, 1350.0, -900.0), 180.0),
}


def _tracker(origin_mm, turn_deg: float) -> Tracker:
    return Tracker(
        position_m=tuple(v * 1e-3 for v in origin_mm),
        rotation_rpy_rad=(0.01, -0.02, np.radians(turn_deg)),
    )


@pytest.fixture(scope="module")
def machine():
    """Table 2 truth, 30 calibration and 20 held-out poses, 5 um Gaussian noise."""
    nominal = Mechanism.from_xml(MODEL)
    params = load_parameter_set(ERRORS, nominal.model)
    values = load_values(ROOT / "scenarios/truth/hexapod_table2.toml", params)
    truth = Mechanism(params.inject(nominal.model, values), name=nominal.name)
    rng = np.random.default_rng(3)
    _, q = random_poses(nominal, 30, rng)
    _, q_new = random_poses(nominal, 20, rng)
    base = forward_batch(truth, q).targets + rng.normal(0.0, 5e-6, (30, 3, 3))
    model = CalibrationModel(nominal, params)
    fit = identify(model, Observations(q, base), unidentifiable="fix")
    held = forward_batch(truth, q_new).targets
    return model, q, base, q_new, held, fit


def _heldout_rms(model, values, q_new, held, registration: Registration) -> float:
    """3D RMS (m) of the held-out poses seen through the fit, in the tracker's frame."""
    fitted = model.nominal.with_model(model.params.inject(model.nominal.model, values))
    predicted = registration.to_tracker(forward_batch(fitted, q_new).targets)
    return float(np.sqrt(np.mean(np.sum((predicted - held) ** 2, axis=-1))))


def test_far_and_turned_tracker_frames_converge_alike(machine):
    model, q, base, q_new, held, fit = machine
    base_heldout = _heldout_rms(model, fit.values, q_new, held, identity())
    values = []
    for origin, turn in FRAMES.values():
        tracker = _tracker(origin, turn)
        res = identify(
            model,
            Observations(q, tracker.in_own_frame(base), frame="tracker"),
            unidentifiable="fix",
        )
        assert res.converged and res.iterations <= LMOptions().max_iterations
        values.append(res.values)
        seen = Registration(*tracker.base_from_tracker)  # held-out readings in this frame
        rms = _heldout_rms(model, res.values, q_new, seen.to_tracker(held), res.registration)
        assert rms < 1.1 * base_heldout, (origin, turn, rms, base_heldout)
        assert res.residual_rms == pytest.approx(fit.residual_rms, rel=0.01)
    # the frame changes neither the fit nor whether it converges (how many steps it took is
    # the CPU's round-off to decide, and not asserted): the same estimates in every frame
    assert np.max(np.abs(np.array(values) - values[0])) < 1e-8  # metres: the same fit


def test_command_line_fit_in_a_far_turned_frame_exits_0(machine, tmp_path, capsys):
    """The issue's case: it exited 3 'did not converge (iteration limit)' at 50 iterations."""
    model, q, base, *_ = machine
    tracker = _tracker(*FRAMES["4500 mm, 180 deg"])
    n = len(q)
    ds = Dataset(
        model=model.nominal.name,
        frame="tracker",
        actuator_names=model.nominal.actuator_names,
        actuator_units=("mm",) * 6,
        target_names=model.nominal.target_names,
        pose_ids=np.arange(n),
        sets=np.array(["calibration"] * n),
        commands=q,
        readings=tracker.in_own_frame(base)[:, :, None, :],
    )
    data = write_dataset(ds, tmp_path / "far.csv")
    argv = ["identify", "--model", str(MODEL), "--errors", str(ERRORS), "--data", str(data)]
    assert main([*argv, "--sigma-mm", "0.005"]) == 0
    assert "converged: True" in capsys.readouterr().out


def test_registration_carried_from_the_centre_back_to_the_readings():
    """:func:`about` maps the same points, and :func:`about_jacobian` is its derivative
    (finite differences)."""
    rng = np.random.default_rng(1)
    points = rng.normal(size=(20, 3)) + np.array([4.0, 1.0, -0.5])
    centre = points.mean(axis=0)
    start = Registration(matrix_from_rotvec([0.3, -1.2, 2.5]), np.array([0.1, 0.2, 0.3]))
    x = np.array([0.05, -0.02, 0.01, 0.02, -0.03, 0.01])
    reg_c = start.moved(x)
    np.testing.assert_allclose(
        about(reg_c, centre).to_base(points), reg_c.to_base(points - centre), atol=1e-14
    )

    def carried(z: np.ndarray) -> np.ndarray:  # (t, phi) of the readings' registration
        return np.concatenate([about(start.moved(z), centre).translation, z[3:]])

    fd = np.zeros((6, 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-7
        fd[:, k] = (carried(x + d) - carried(x - d)) / 2e-7
    np.testing.assert_allclose(about_jacobian(start, x, centre), fd, atol=1e-7)


def _rosenbrock(k: float):
    """r = (k (y - x^2), 1 - x): a curved valley with its exact minimum 0 at (1, 1)."""

    def residual(z: np.ndarray):
        return np.array([k * (z[1] - z[0] ** 2), 1.0 - z[0]]), None

    def jacobian(z: np.ndarray, _state) -> np.ndarray:
        return np.array([[-2.0 * k * z[0], k], [-1.0, 0.0]])

    return residual, jacobian


def test_geodesic_acceleration_follows_a_curved_valley():
    """Rosenbrock's valley (k = 100) from the classic start (-1.2, 1): both reach (1, 1)
    exactly; the accelerated steps need fewer iterations (34 against 68)."""
    residual, jacobian = _rosenbrock(100.0)
    start = np.array([-1.2, 1.0])
    runs = {
        geo: levenberg_marquardt(
            residual, jacobian, start, LMOptions(max_iterations=500, geodesic=geo)
        )
        for geo in (False, True)
    }
    for res in runs.values():
        assert res.converged
        np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-10)
    assert runs[True].iterations < 0.75 * runs[False].iterations
