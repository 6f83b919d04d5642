"""What liu_vs_ols's estimates figure shows: the combinations of the kept parameters the plan
reads (singular directions of H in mm and deg), their estimates, standard errors and the
sentence that says why the rest cannot be read."""

from __future__ import annotations

import numpy as np

from calib.estimators.ols import OLS
from scenarios.studies.liu_vs_ols.combinations import (
    drawn_bound,
    plan_combinations,
    sentence,
    summary_entry,
)

NAMES = ["a.dx", "b.encoder", "c.dalpha", "d.dz"]


def _problem(eps: float = 1e-6, sigma: float = 5e-6, seed: int = 3):
    """Four columns, the second nearly the first (a cancelling pair): readings in metres per
    mm or deg, a truth of a few hundredths and readings with noise ``sigma``."""
    rng = np.random.default_rng(seed)
    h = rng.normal(size=(60, 4)) * 1e-3
    h[:, 1] = h[:, 0] + eps * rng.normal(size=60)
    truth = np.array([0.02, -0.01, 0.03, 0.015])
    y = h @ truth + rng.normal(0.0, sigma, size=60)
    return h, truth, y


def test_the_combinations_are_the_estimate_seen_along_the_singular_directions():
    h, truth, y = _problem()
    est = OLS().fit(h, y)
    c = plan_combinations(h, est.x, est.covariance, truth, 0.04, NAMES)
    # orthonormal directions: the combinations hold the whole estimate and the whole truth
    np.testing.assert_allclose(c.directions @ c.directions.T, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(c.directions.T @ c.estimate, est.x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(c.directions.T @ c.truth, truth, rtol=1e-10, atol=1e-12)
    # OLS's covariance is sigma2 (H'H)^-1: along a right singular vector, sigma / s
    s = np.linalg.svd(h, compute_uv=False)
    np.testing.assert_allclose(np.sort(c.std), np.sort(np.sqrt(est.sigma2) / s), rtol=1e-8)
    assert np.all(np.diff(c.std) >= 0)  # smallest standard error first
    # each combination's change of the readings per unit: s / sqrt(n), in mm
    np.testing.assert_allclose(
        np.sort(c.rms_per_unit_mm), np.sort(s / np.sqrt(60) * 1e3), rtol=1e-12
    )


def test_the_cancelling_pair_is_the_one_combination_not_readable():
    h, truth, y = _problem()
    est = OLS().fit(h, y)
    c = plan_combinations(h, est.x, est.covariance, truth, 0.04, NAMES)
    assert c.readable.tolist() == [True, True, True, False]
    # its direction is the pair's difference, (1, -1) / sqrt(2), signed + on the larger
    np.testing.assert_allclose(np.abs(c.directions[-1, :2]), [2**-0.5] * 2, atol=1e-3)
    assert c.directions[-1, 0] * c.directions[-1, 1] < 0
    assert c.unreadable_members() == ["a.dx", "b.encoder"]
    assert c.label(3).startswith(("+0.71 a.dx -0.71 b.encoder", "+0.71 b.encoder -0.71 a.dx"))
    # the pair's estimates are off the truth by more than the range drawn (their difference's
    # standard error is sigma / s_min, about 0.9 here), their sum is not: the sum is read
    assert c.std[-1] > 0.5 and np.min(np.abs(est.x[:2] - truth[:2])) > 0.04
    assert abs(est.x[0] + est.x[1] - truth[0] - truth[1]) < 0.01


def test_the_sentence_follows_the_numbers():
    h, truth, y = _problem()
    est = OLS().fit(h, y)
    c = plan_combinations(h, est.x, est.covariance, truth, 0.04, NAMES)
    entry = summary_entry(c, 0.005, 60)
    entry["largest_member_estimate"] = float(np.max(np.abs(est.x[:2])))
    text = sentence(entry)
    assert "fix 3 of the 4 combinations" in text and "The other 1 move the 60" in text
    assert f"up to {entry['largest_member_estimate']:.3g} mm or deg" in text
    assert "(a.dx, b.encoder)" in text and "+-0.04 the errors were drawn in" in text
    lo, hi = entry["unreadable_std"]
    assert lo == hi == c.std[-1] and f"{lo:.2g}-{hi:.2g} mm or deg" in text
    # a wider range drawn: every combination readable, and the sentence says so
    wide = summary_entry(plan_combinations(h, est.x, est.covariance, truth, 1e6, NAMES), 0.005, 60)
    assert sentence(wide).endswith("every kept parameter can be read.")
    assert wide["unreadable_std"] == [] and wide["unreadable_members"] == []


def test_the_bound_is_the_widest_range_drawn():
    drawn = {"translation_mm": 0.04, "rotation_deg": 0.04, "encoder_mm": 3.0, "encoder_deg": 0.1}
    assert drawn_bound(drawn, 9.0) == 3.0
    assert drawn_bound({"translation_mm": 1.0}, 9.0) == 1.0
    assert drawn_bound(None, 9.0) == 9.0
