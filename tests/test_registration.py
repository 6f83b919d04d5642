"""The tracker in its own frame, 4.5 m away and turned 100 degrees; a prior for weak
parameters. Machine: the generic 6R arm (serial, no masses), one reflector."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations
from calib.fit.prior import Prior, PriorSpec, collinear_groups, weakly_identified
from calib.fit.registration import (
    Registration,
    RegistrationError,
    initial_registration,
    registration_jacobian,
)
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rotvec
from twin.tracker import Tracker, TrackerNoise

ROOT = Path(__file__).resolve().parent.parent
LINK1 = ("link1.alpha", "link1.a", "link1.d", "link1.theta")


@pytest.fixture(scope="module")
def arm():
    nominal = Mechanism.from_xml(ROOT / "models/arm6r.xml")
    params = load_parameter_set(ROOT / "models/arm6r.params.toml", nominal.model)
    return nominal, params


def _truth(arm, seed: int, zero_link1: bool = False):
    nominal, params = arm
    rng = np.random.default_rng(seed)
    values = rng.uniform(-1, 1, len(params)) * np.where(params.is_angle, np.radians(0.05), 5e-4)
    if zero_link1:
        values[[params.index(n) for n in LINK1]] = 0.0
    return values, nominal.with_model(params.inject(nominal.model, values))


def _joints(arm, n: int, seed: int) -> np.ndarray:
    nominal, _ = arm
    lo, hi = nominal.actuator_range.T
    return np.random.default_rng(seed).uniform(0.8 * lo, 0.8 * hi, (n, nominal.n_actuators))


TRACKER = Tracker(
    position_m=(4.0, 2.0, 0.5),
    noise=TrackerNoise.none(),
    rotation_rpy_rad=(0.02, -0.03, np.radians(100.0)),
)


def test_kabsch_start_and_registration_jacobian():
    rng = np.random.default_rng(0)
    base = rng.normal(size=(30, 3))
    rot, t = matrix_from_rotvec([0.3, -1.2, 1.5]), np.array([4.0, 1.0, -0.5])
    tracker = (base - t) @ rot
    reg = initial_registration(tracker, base)
    np.testing.assert_allclose(reg.rotation, rot, atol=1e-12)
    np.testing.assert_allclose(reg.translation, t, atol=1e-12)
    x = np.concatenate([reg.translation, [0.01, -0.02, 0.03]])
    jac = registration_jacobian(reg, x, tracker)
    fd = np.zeros_like(jac)
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-7
        fd[:, k] = (reg.moved(x + d).to_base(tracker) - reg.moved(x - d).to_base(tracker)).ravel()
    np.testing.assert_allclose(jac, fd / 2e-7, atol=1e-7)
    assert Registration.from_dict(reg.as_dict()).to_base(tracker) == pytest.approx(base)


def test_collinear_readings_cannot_register():
    line = np.outer(np.linspace(0, 1, 10), [1.0, 2.0, 3.0])
    with pytest.raises(RegistrationError, match="lie on a line"):
        initial_registration(line, line + 1.0)
    with pytest.raises(RegistrationError, match="at least 3 points"):
        initial_registration(line[:2], line[:2])


def test_tracker_frame_noise_free_fits_exactly_and_predicts_new_poses(arm):
    nominal, params = arm
    _, truth = _truth(arm, 1)
    q, q_new = _joints(arm, 40, 2), _joints(arm, 15, 3)
    obs = Observations(q, TRACKER.in_own_frame(forward_batch(truth, q).targets), frame="tracker")
    res = identify(CalibrationModel(nominal, params), obs, unidentifiable="fix")
    assert set(res.redundant_with_registration) == set(LINK1)
    for name in LINK1:
        assert "registration" in res.report.unidentifiable[name]
    assert res.residual_rms < 1e-11
    # the identified arm, seen through the identified registration, predicts new readings
    fitted = nominal.with_model(params.inject(nominal.model, res.values))
    predicted = TRACKER.in_own_frame(forward_batch(truth, q_new).targets)
    seen = res.registration.to_tracker(forward_batch(fitted, q_new).targets)
    assert np.max(np.abs(seen - predicted)) < 1e-9


def test_registration_recovered_when_nothing_redundant_is_in_the_truth(arm):
    nominal, params = arm
    _, truth = _truth(arm, 4, zero_link1=True)
    q = _joints(arm, 40, 5)
    obs = Observations(q, TRACKER.in_own_frame(forward_batch(truth, q).targets), frame="tracker")
    res = identify(CalibrationModel(nominal, params), obs, unidentifiable="fix")
    rot, t = TRACKER.base_from_tracker
    np.testing.assert_allclose(res.registration.translation, t, atol=1e-9)
    np.testing.assert_allclose(res.registration.rotation, rot, atol=1e-9)
    assert res.registration_std is not None and np.all(res.registration_std < 1e-9)


def test_prior_keeps_weak_parameters_physical_and_helps_held_out(arm):
    """12 poses in a small volume (5 % of each joint range around home), 20 um noise: the
    errors are identifiable but weakly, estimates wander to several mm; a prior of the
    truth's size (0.5 mm, 0.05 deg) keeps them physical and lowers the held-out 3D error in
    the same volume, on average over truth draws."""
    nominal, params = arm
    lo, hi = nominal.actuator_range.T
    home = nominal.home_qpos[nominal.actuator_qpos]
    spec = PriorSpec(length_mm=0.5, angle_deg=0.05)
    prior = Prior(spec.std_si(params.is_angle), noise_sigma_m=20e-6)
    noisy = Tracker(position_m=(4.0, 2.0, 0.5), noise=TrackerNoise("gaussian", 20e-6, 0.0))
    model = CalibrationModel(nominal, params)
    gain, sizes = [], []
    for seed in range(5):
        _, truth = _truth(arm, seed)
        rng = np.random.default_rng(seed + 100)
        q, q_new = (home + rng.uniform(-1, 1, (n, 6)) * 0.05 * (hi - lo) / 2 for n in (12, 60))
        obs = Observations(q, noisy.measure_averaged(forward_batch(truth, q).targets, rng))
        free = identify(model, obs, unidentifiable="fix")
        held = identify(model, obs, unidentifiable="fix", prior=prior)
        truth_new = forward_batch(truth, q_new).targets

        def heldout(values, truth_new=truth_new, q_new=q_new):
            fitted = nominal.with_model(params.inject(nominal.model, values))
            e = np.linalg.norm(forward_batch(fitted, q_new).targets - truth_new, axis=-1)
            return float(np.sqrt(np.mean(e**2)))

        gain.append(heldout(free.values) - heldout(held.values))
        sizes.append(
            (
                np.max(np.abs(params.to_display(free.values))),
                np.max(np.abs(params.to_display(held.values))),
            )
        )
        weak = weakly_identified(free.names, free.std_errors, params, spec)
        assert len(weak) >= 10 and all(w["std"] > 0.5 * w["prior_range"] for w in weak)
        assert np.nanmax(held.std_errors) < 0.5 * np.nanmax(free.std_errors)
    sizes = np.array(sizes)
    assert np.all(sizes[:, 0] > 1.0) and np.all(sizes[:, 1] < 1.0)  # mm or deg
    assert np.mean(gain) > 0.005e-3  # held-out 3D RMS lower by more than 5 um on average


def test_collinear_groups_join_pairs():
    cov = np.eye(4)
    cov[0, 1] = cov[1, 0] = 0.99
    cov[1, 2] = cov[2, 1] = 0.97
    assert collinear_groups(("a", "b", "c", "d"), cov) == [["a", "b", "c"]]


def test_prior_spec_parsing():
    assert PriorSpec.parse("length=1,angle=0.1") == PriorSpec(1.0, 0.1)
    assert PriorSpec.parse("angle=0.2") == PriorSpec(None, 0.2)
    for bad, message in (("len=1", "kind=value"), ("length=x", "not a number"), ("", "empty")):
        with pytest.raises(ValueError, match=message):
            PriorSpec.parse(bad)
