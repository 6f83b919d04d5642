"""Robust identification: gross outliers (a broken beam, the wrong reflector) are rejected.

Hexapod with the Table 2 truth, 5 um Gaussian tracker noise per coordinate; a few readings
(one reading = one pose x target, 3 coordinates) displaced by 2 mm in random directions.
The estimate must come from the good readings only, clean data must come out exactly as
plain least squares, and the residual diagnosis must not read the outliers as an effect.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calib.diagnosis.core import default_candidates, diagnose
from calib.estimators.levenberg_marquardt import reweighted_levenberg_marquardt
from calib.exceptions import CalibError, TooManyOutliersError
from calib.fit.identification import Rejection, RobustOptions, identify, robust_scale
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations
from calib.fit.robust import suspect_outliers
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism
from twin.workspace import random_poses

SIGMA = 5e-6  # metres per coordinate
JUMP = 2e-3  # a gross outlier: 2 mm in a random direction
LEGS = tuple(f"leg{i}" for i in range(1, 7))


@pytest.fixture(scope="module")
def bench(hexapod, hexapod_params, table2_values):
    truth = Mechanism(hexapod_params.inject(hexapod.model, table2_values))
    _, test_commands = random_poses(hexapod, 40, np.random.default_rng(99))
    return {
        "model": CalibrationModel(hexapod, hexapod_params),
        "truth": truth,
        "test_commands": test_commands,
        "test_targets": forward_batch(truth, test_commands).targets,
    }


def _clean(bench, n_poses: int, seed: int) -> tuple[Observations, np.random.Generator]:
    rng = np.random.default_rng(seed)
    _, commands = random_poses(bench["model"].nominal, n_poses, rng)
    exact = forward_batch(bench["truth"], commands).targets
    return Observations(commands, exact + rng.normal(0.0, SIGMA, exact.shape)), rng


def _spoil(obs: Observations, fraction: float, rng: np.random.Generator):
    """Displace round(fraction * readings) readings by JUMP; returns (obs, {(pose, target)})."""
    n_poses, n_targets = obs.measured.shape[:2]
    k = max(1, round(fraction * n_poses * n_targets))
    flat = rng.choice(n_poses * n_targets, size=k, replace=False)
    direction = rng.normal(size=(k, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    measured = obs.measured.copy()
    measured.reshape(-1, 3)[flat] += JUMP * direction
    bad = {(int(i) // n_targets, int(i) % n_targets) for i in flat}
    return Observations(obs.commands, measured), bad


def _heldout_rms(bench, values: np.ndarray) -> float:
    """3D RMS target error on fresh poses (noise-free truth), metres."""
    pred = bench["model"].predict(values, bench["test_commands"]).targets
    return float(np.sqrt(np.mean(np.sum((pred - bench["test_targets"]) ** 2, axis=2))))


@pytest.fixture(scope="module")
def spoiled80(bench):
    """80 poses, 3 % of the readings (7 of 240) displaced: clean and robust fits."""
    clean, rng = _clean(bench, 80, 5)
    obs, bad = _spoil(clean, 0.03, rng)
    model = bench["model"]
    return clean, obs, bad, identify(model, clean), identify(model, obs)


# ----------------------------------------------------------------------------- clean data
def test_clean_data_rejects_nothing_and_equals_least_squares(bench, spoiled80):
    clean, _, _, robust, _ = spoiled80
    plain = identify(bench["model"], clean, robust=False)
    assert robust.rejected == () and plain.rejected == ()
    # equal up to where Levenberg-Marquardt stops: the closure solves start warm from the
    # model's previous call, so their round-off (1e-15 m) differs between the two fits and
    # moves the stopping point by up to a few 1e-10 m along ill-determined directions
    np.testing.assert_allclose(robust.values, plain.values, rtol=0, atol=1e-9)
    np.testing.assert_allclose(robust.std_errors, plain.std_errors, rtol=1e-6)
    assert robust.residual_rms == pytest.approx(plain.residual_rms, rel=1e-9)
    # the robust scale estimates the per-coordinate noise
    assert robust.robust_scale_m == pytest.approx(SIGMA, rel=0.15)


# ----------------------------------------------------------------------------- outliers
@pytest.mark.parametrize(("n_poses", "fraction", "seed"), [(60, 0.01, 1), (100, 0.05, 2)])
def test_displaced_readings_are_rejected_and_the_estimate_survives(bench, n_poses, fraction, seed):
    clean, rng = _clean(bench, n_poses, seed)
    obs, bad = _spoil(clean, fraction, rng)
    model = bench["model"]
    result = identify(model, obs)
    assert {(r.pose_index, r.target_index) for r in result.rejected} == bad
    for r in result.rejected:
        assert isinstance(r, Rejection)
        assert r.residual_m == pytest.approx(JUMP, rel=0.05)
    reference = _heldout_rms(bench, identify(model, clean).values)
    assert _heldout_rms(bench, result.values) < 1.2 * reference
    assert result.robust_scale_m == pytest.approx(SIGMA, rel=0.2)
    assert result.converged


def test_outliers_spoil_plain_least_squares(bench, spoiled80):
    """What the robust fit guards against: without it the same data gives a far worse
    machine, and the fit's own standard errors blow up."""
    _, obs, bad, clean_fit, robust = spoiled80
    plain = identify(bench["model"], obs, robust=False)
    assert plain.rejected == ()
    reference = _heldout_rms(bench, clean_fit.values)
    assert _heldout_rms(bench, plain.values) > 5 * reference
    assert _heldout_rms(bench, robust.values) < 1.2 * reference
    assert {(r.pose_index, r.target_index) for r in robust.rejected} == bad
    # ordered by pose, then target
    keys = [(r.pose_index, r.target_index) for r in robust.rejected]
    assert keys == sorted(keys)


def test_statistics_come_from_the_kept_readings(spoiled80):
    _, _, _, clean_fit, robust = spoiled80
    # residual and standard errors at the noise level, as on clean data (240 - 7 readings)
    assert robust.residual_rms == pytest.approx(clean_fit.residual_rms, rel=0.1)
    ratio = robust.std_errors / clean_fit.std_errors
    assert np.all((ratio > 0.9) & (ratio < 1.15)), ratio


def test_too_many_outliers_are_refused(bench):
    clean, rng = _clean(bench, 30, 7)
    obs, _ = _spoil(clean, 0.4, rng)  # 36 of 90 readings
    with pytest.raises(TooManyOutliersError, match=r"of 90 readings .* more than 20 %") as info:
        identify(bench["model"], obs)
    count = int(str(info.value).split(" of 90")[0])
    assert count > 18
    assert "wrong target" in str(info.value)
    assert isinstance(info.value, CalibError)


# ----------------------------------------------------------------------------- diagnosis
def test_diagnosis_does_not_read_outliers_as_an_effect(bench, spoiled80):
    _, obs, _, _, robust = spoiled80
    d = diagnose(bench["model"], obs, robust, SIGMA)
    assert not d.excess and d.chosen == "none"
    assert d.residual_rms_mm == pytest.approx(SIGMA * 1e3, rel=0.15)
    # the same result with its rejections forgotten: the outliers are a large excess
    # (one cheap candidate is enough to show it)
    thermal = [c for c in default_candidates(LEGS) if c.name == "thermal_growth"]
    forgot = dataclasses.replace(robust, rejected=())
    blind = diagnose(bench["model"], obs, forgot, SIGMA, candidates=thermal)
    assert blind.excess and blind.residual_rms_mm > 10 * SIGMA * 1e3


# ----------------------------------------------------------------------------- pieces
def test_robust_scale_is_sigma_for_gaussian_noise_and_ignores_a_minority():
    rng = np.random.default_rng(0)
    norms = np.linalg.norm(rng.normal(0.0, 2.0, size=(4000, 3)), axis=1)
    assert robust_scale(norms, 0) == pytest.approx(2.0, rel=0.03)
    spoiled = norms.copy()
    spoiled[:400] = 1e3  # 10 % gross outliers move the median only a little
    assert robust_scale(spoiled, 0) == pytest.approx(2.0, rel=0.12)
    # fitting p parameters to m coordinates shrinks residuals by sqrt((m - p) / m)
    assert robust_scale(norms, 6000) == pytest.approx(robust_scale(norms, 0) * np.sqrt(2))


def test_reweighted_levenberg_marquardt_downweights_outliers():
    """A straight line through 3D points with two gross outliers (soft-L1 weights)."""
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 1.0, 40)
    truth = np.array([1.0, -2.0, 0.5, 0.3, 0.1, -0.4])  # offset (3) + direction (3)

    def line(x):
        return x[:3] + t[:, None] * x[3:]

    data = line(truth) + rng.normal(0.0, 1e-3, (40, 3))
    data[[5, 30]] += 1.0

    def residual(x):
        return (data - line(x)).reshape(-1), None

    def jacobian(x, _state):
        jac = np.zeros((40, 3, 6))
        jac[:, :, :3] = -np.eye(3)
        jac[:, :, 3:] = -t[:, None, None] * np.eye(3)
        return jac.reshape(-1, 6)

    def weights(r):
        norms = np.linalg.norm(r.reshape(-1, 3), axis=1)
        c = 3 * max(robust_scale(norms, 6), 1e-12)
        return 1.0 / np.sqrt(1.0 + (norms / c) ** 2)

    fit = reweighted_levenberg_marquardt(residual, jacobian, np.zeros(6), weights, group=3)
    assert fit.rounds > 1 and fit.iterations >= fit.rounds
    assert fit.weights.shape == (40,)
    assert fit.weights[[5, 30]].max() < 0.02 < 0.5 < fit.weights[[0, 20, 39]].min()
    np.testing.assert_allclose(fit.fit.x, truth, atol=3e-3)
    np.testing.assert_allclose(fit.residual.reshape(40, 3), data - line(fit.fit.x), atol=1e-12)


# ----------------------------------------------------------------------------- the screen
def _screen(model: CalibrationModel, obs: Observations, fit) -> bool:
    """The screen at a least-squares fit: its residual and Jacobian, as identify builds them."""
    pred = model.predict(fit.values, obs.commands)
    residual = (obs.measured - pred.targets).reshape(-1)
    jac = -model.jacobian(fit.values, pred)[:, fit.estimated]
    return suspect_outliers(residual, jac, residual.size // 3, jac.shape[1], RobustOptions())


def test_the_screen_runs_the_robust_stage_exactly_when_outliers_may_hide(bench, spoiled80):
    clean, obs, bad, screened_clean, screened_spoiled = spoiled80
    model = bench["model"]
    assert not _screen(model, clean, identify(model, clean, robust=False))
    assert _screen(model, obs, identify(model, obs, robust=False))
    # without the screen (the robust stage always run) the answers are the same
    always = RobustOptions(screen=0.0)
    full_clean = identify(model, clean, robust_options=always)
    assert full_clean.rejected == screened_clean.rejected == ()
    np.testing.assert_allclose(screened_clean.values, full_clean.values, rtol=0, atol=1e-9)
    full_spoiled = identify(model, obs, robust_options=always)
    assert {(r.pose_index, r.target_index) for r in full_spoiled.rejected} == bad
    keys = [(r.pose_index, r.target_index) for r in screened_spoiled.rejected]
    assert keys == [(r.pose_index, r.target_index) for r in full_spoiled.rejected]
    np.testing.assert_allclose(screened_spoiled.values, full_spoiled.values, rtol=0, atol=1e-9)


def test_the_screen_unmasks_an_outlier_at_a_high_leverage_pose(bench):
    """A single displaced reading at the pose with the largest leverage: least squares pulls
    towards it, its own residual shrinks, its deleted residual does not."""
    clean, _ = _clean(bench, 40, 11)
    model = bench["model"]
    plain = identify(model, clean, robust=False)
    pred = model.predict(plain.values, clean.commands)
    jac = model.jacobian(plain.values, pred)[:, plain.estimated]
    hat = jac @ np.linalg.solve(jac.T @ jac, jac.T)
    leverage = np.diag(hat).reshape(40, -1).sum(axis=1)  # per pose, all its targets
    pose = int(np.argmax(leverage))
    measured = clean.measured.copy()
    measured[pose, 0] += [0.2 * JUMP, 0.0, 0.0]
    spoiled = Observations(clean.commands, measured)
    assert leverage[pose] > 2 * np.median(leverage)
    assert _screen(model, spoiled, identify(model, spoiled, robust=False))
    result = identify(model, spoiled)
    assert [(r.pose_index, r.target_index) for r in result.rejected] == [(pose, 0)]
