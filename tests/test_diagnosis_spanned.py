"""A candidate's column the geometry spans is one the data cannot see: its parameter stays 0
whatever the round-off of the projection leaves of it (an ill-conditioned geometry's basis
holds its span to about eps x its condition number), and the fit of the other columns is the
fit without it."""

from __future__ import annotations

import numpy as np

from calib.diagnosis.problem import SPANNED, Problem, fit


def test_a_column_the_geometry_spans_stays_at_zero():
    rng = np.random.default_rng(3)
    n, rows, p = 200, 3, 6
    geo = rng.normal(size=(n, rows, p))
    geo[:, :, 5] = geo[:, :, 4] + 1e-7 * rng.normal(size=(n, rows))  # condition ~1e7
    # in the geometry's span, along its weakest direction, where the basis holds the span
    # least well (about eps x the condition number)
    spanned = 1e7 * (geo[:, :, 5] - geo[:, :, 4])
    seen = rng.normal(size=(n, rows))
    r = 2e-3 * seen + geo @ rng.normal(0, 1e-3, p) + rng.normal(0, 1e-6, (n, rows))
    prob = Problem(r, geo)
    poses = np.ones(n, bool)
    q = prob.basis(poses)
    left = spanned.reshape(-1) - q @ (q.T @ spanned.reshape(-1))
    # what the projection leaves is round-off, far below the column, above the old RCOND test
    assert 1e-13 < np.linalg.norm(left) / np.linalg.norm(spanned) < SPANNED
    both = fit(prob, [spanned[:, :, None], seen[:, :, None]], poses)
    alone = fit(prob, [seen[:, :, None]], poses)
    assert both.theta[0] == 0.0
    np.testing.assert_allclose(both.theta[1], 2e-3, rtol=1e-3)
    # the same fit to round-off (one column or two go through different BLAS paths)
    np.testing.assert_allclose(both.theta[1:], alone.theta, rtol=1e-12)
