"""The residual correction's pieces: kernel ridge identities, leave-one-out, cross-validation,
the guard, the file round trip, the cap on training poses, the offer rule, the twin effect."""

from __future__ import annotations

import numpy as np
import pytest

import calib.correction.kernel_ridge as kr_mod
from calib.correction.correction import (
    CorrectionFileError,
    ResidualCorrection,
    feature_names,
    guard_radius,
)
from calib.correction.kernel_ridge import (
    CrossValidation,
    cross_validate,
    fit_kernel_ridge,
    sq_dist,
    standardisation,
)
from calib.correction.offer import fit_and_judge
from calib.correction.stages import stage_table


def _smooth(x: np.ndarray) -> np.ndarray:
    """A smooth map of 3 features to one reading's 3D error (m)."""
    return 1e-3 * np.stack(
        [np.sin(x[:, 0]) * np.cos(x[:, 1]), np.cos(x[:, 2]), x[:, 0] * x[:, 1] / 4], axis=1
    )


def test_mean_is_the_ridge_solution_and_std_the_gp_posterior():
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, (40, 3))
    y = _smooth(x)
    kr = fit_kernel_ridge(x, y, 0.4, 1e-2)
    mean, scale = standardisation(x)
    z = (x - mean) / scale
    c = np.exp(-0.5 * sq_dist(z, z) / (0.4**2 * 3))
    alpha = np.linalg.solve(c + 1e-2 * np.eye(40), y)
    xs = rng.uniform(-1, 1, (7, 3))
    zs = (xs - mean) / scale
    ks = np.exp(-0.5 * sq_dist(zs, z) / (0.4**2 * 3))
    m, s = kr.predict(xs)
    np.testing.assert_allclose(m, ks @ alpha, rtol=1e-9, atol=1e-15)
    s2 = np.sum(y * alpha) / y.size  # the maximum-likelihood signal variance
    var = s2 * (1 - np.einsum("ij,ji->i", ks, np.linalg.solve(c + 1e-2 * np.eye(40), ks.T)))
    np.testing.assert_allclose(s, np.sqrt(var), rtol=1e-7)


def test_one_training_pose_std_is_the_analytic_posterior():
    # one pose: k* = 1 at itself, so var = s2 (1 - 1 / (1 + r)) = s2 r / (1 + r)
    x, y = np.array([[0.3, -0.2]]), np.array([[2e-3, 0.0, -1e-3]])
    kr = fit_kernel_ridge(x, y, 0.5, 0.1, mean=np.zeros(2), scale=np.ones(2))
    s2 = np.sum(y**2) / (1.1 * 3)
    _, s = kr.predict(x)
    assert s[0] == pytest.approx(np.sqrt(s2 * 0.1 / 1.1), rel=1e-12)


def test_leave_one_out_equals_refits_without_each_pose():
    rng = np.random.default_rng(1)
    x = rng.uniform(-1, 1, (25, 3))
    y = _smooth(x) + 1e-5 * rng.standard_normal((25, 3))
    mean, scale = standardisation(x)
    kr = fit_kernel_ridge(x, y, 0.6, 1e-2, mean, scale)
    loo = kr.loo_mean()
    for i in (0, 7, 24):
        keep = np.arange(25) != i
        other = fit_kernel_ridge(x[keep], y[keep], 0.6, 1e-2, mean, scale)
        np.testing.assert_allclose(loo[i], other.predict(x[i : i + 1])[0][0], atol=1e-11)


def test_cross_validation_equals_fold_refits():
    rng = np.random.default_rng(2)
    x = rng.uniform(-1, 1, (60, 3))
    y = _smooth(x)
    labels = np.repeat(np.arange(4), 15)  # blocks of the order
    cv = cross_validate(x, y, labels, (0.3, 0.8), (1e-3, 0.1))
    mean, scale = standardisation(x)
    for i, ls in enumerate((0.3, 0.8)):
        for j, r in enumerate((1e-3, 0.1)):
            sse = 0.0
            for f in range(4):
                tr = labels != f
                kr = fit_kernel_ridge(x[tr], y[tr], ls, r, mean, scale)
                sse += np.sum((y[~tr] - kr.predict(x[~tr], with_std=False)[0]) ** 2)
            # the fit's own arithmetic (Cholesky of C + r I): the same to round-off
            assert cv.sse[i, j] == pytest.approx(sse, rel=1e-12)
    assert cv.sse.min() == cv.sse[(0.3, 0.8).index(cv.length_scale), (1e-3, 0.1).index(cv.ratio)]


def test_guard_radius_drops_the_far_poses_the_correction_made_worse():
    d = np.arange(20, dtype=float)  # distances 0..19
    before = np.ones((20, 3))
    after = np.where((d >= 15)[:, None], 2.0, 0.5) * np.ones((20, 3))
    cv = CrossValidation(np.zeros((1, 1)), 1.0, 1.0, before, after, d)
    # windows of 5 (GUARD_GROUP; 10 % is 2), per pose SSE before 3, after 12 (d >= 15) or
    # 0.75: the window 19..15 is worse, ... 15..11 holds 12 + 4 x 0.75 = 15, not below 15;
    # 14..10 holds 5 x 0.75 < 15: the radius is its farthest distance, 14
    assert guard_radius(cv) == 14.0
    all_worse = CrossValidation(np.zeros((1, 1)), 1.0, 1.0, before, 2 * before, d)
    assert guard_radius(all_worse) == 0.0


def _correction(x, y, radius=1.0) -> ResidualCorrection:
    kr = fit_kernel_ridge(x, y, 0.5, 1e-2)
    names, units = feature_names(("A1", "A2"), (False, True), False)
    return ResidualCorrection(kr, radius, names, units, 1, {"reason": "test"})


def test_guard_and_round_trip_through_the_file_block():
    rng = np.random.default_rng(3)
    x = np.column_stack([rng.uniform(-1, 1, 30), rng.uniform(0, 0.2, 30)])
    corr = _correction(x, _smooth(np.column_stack([x, x[:, :1]])))
    far = np.array([[10.0, 0.1], [0.0, 0.1]])
    p = corr.predict(far)
    assert not p["inside"][0] and np.all(p["mean"][0] == 0.0)
    assert p["inside"][1] and np.any(p["mean"][1] != 0.0)
    back = ResidualCorrection.from_dict(corr.to_dict("m"), "here", "m")
    q = back.predict(far)
    np.testing.assert_allclose(q["mean"], p["mean"], rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(q["std"], p["std"], rtol=1e-9)
    with pytest.raises(CorrectionFileError, match="for model 'm', not 'other'"):
        ResidualCorrection.from_dict(corr.to_dict("m"), "here", "other")
    bad = {**corr.to_dict("m"), "weights_mm": [[1.0, 2.0]]}
    with pytest.raises(CorrectionFileError, match="here"):
        ResidualCorrection.from_dict(bad, "here", "m")


def test_training_poses_are_capped_evenly(monkeypatch):
    monkeypatch.setattr(kr_mod, "MAX_TRAINING_POSES", 50)
    x = np.linspace(0, 1, 400)[:, None] * np.ones((1, 2))
    kr = fit_kernel_ridge(x, np.zeros((400, 3)), 0.5, 0.1)
    assert kr.z_train.shape == (50, 2)  # memory: 50^2, not 400^2
    # the first pose kept, standardised by the whole set's scaling: a grid of n points with
    # spacing h has standard deviation h sqrt((n^2 - 1) / 12)
    assert kr.z_train[0, 0] == pytest.approx(-0.5 / (np.sqrt((400**2 - 1) / 12) / 399), rel=1e-9)


def test_offered_for_structure_refused_for_noise():
    rng = np.random.default_rng(4)
    x = rng.uniform(-1, 1, (200, 3))
    labels = np.repeat(np.arange(5), 40)
    names, units = feature_names(("A1", "A2", "A3"), (False,) * 3, False)
    sigma = 2e-5
    smooth = _smooth(x) + sigma * rng.standard_normal((200, 3))
    ok = fit_and_judge(x, smooth, np.ones(200, bool), labels, sigma, names, units)
    assert ok.offered, ok.reason
    assert ok.numbers["cv"]["after"]["rms_mm"] < 0.2 * ok.numbers["cv"]["before"]["rms_mm"]
    noise = sigma * rng.standard_normal((200, 3))
    no = fit_and_judge(x, noise, np.ones(200, bool), labels, sigma, names, units)
    assert not no.offered and no.reason.startswith("not offered")


def test_stage_shares_sum_to_the_whole():
    rows = stage_table({"nominal": 10.0, "geometry": 3.0, "effect": 2.0, "correction": 1.0})
    shares = {r["stage"]: r["share_percent"] for r in rows}
    assert shares["geometry"] == pytest.approx(91.0)  # (100 - 9) / 100
    assert shares["effect"] == pytest.approx(5.0)
    assert shares["correction"] == pytest.approx(3.0)
    assert sum(shares.values()) == pytest.approx(100.0)


def test_cross_coupling_deflects_by_other_joints():
    from twin.effects import CrossCoupling
    from twin.exceptions import ModelError
    from twin.mechanism import Mechanism

    mech = Mechanism.from_xml("models/arm6r.xml")
    c = np.array([[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]])
    eff = CrossCoupling(terms=((0, 1, 3, 1e-3), (2, 4, 5, -2e-3)))
    q = eff.apply(mech, c, np.arange(1))
    expect = c.copy()
    expect[0, 0] += 1e-3 * np.sin(0.2) * np.cos(0.4)
    expect[0, 2] += -2e-3 * np.sin(0.5) * np.cos(0.6)
    np.testing.assert_allclose(q, expect, rtol=0, atol=1e-16)
    drawn = CrossCoupling(seed=5).coupling(mech)
    assert drawn == CrossCoupling(seed=5).coupling(mech)  # seeded
    assert all(i not in (j, k) and j != k for i, j, k, _ in drawn)
    with pytest.raises(ModelError, match="name no actuator"):
        CrossCoupling(terms=((0, 1, 9, 1e-3),)).coupling(mech)
