"""Linear estimators (OLS, Liu, ridge, PCR) against independent computations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from calib.estimators.liu import Liu, liu_d_optimal, liu_mse
from calib.estimators.ols import OLS
from calib.estimators.pcr import PCR
from calib.estimators.registry import make_estimator
from calib.estimators.ridge import Ridge, gcv_score

# Hald (1952) cement data (Woods, Steinour & Starke 1932), the classic collinear example
# of the Liu (1993) and ridge literature; used without intercept.
HALD_X = np.array(
    [[7, 26, 6, 60], [1, 29, 15, 52], [11, 56, 8, 20], [11, 31, 8, 47], [7, 52, 6, 33],
     [11, 55, 9, 22], [3, 71, 17, 6], [1, 31, 22, 44], [2, 54, 18, 22], [21, 47, 4, 26],
     [1, 40, 23, 34], [11, 66, 9, 12], [10, 68, 8, 12]], dtype=float)  # fmt: skip
HALD_Y = np.array(
    [78.5, 74.3, 104.3, 87.6, 95.9, 109.2, 102.7, 72.5, 93.1, 115.9, 83.8, 113.3, 109.4]
)


def liu_reference(x: np.ndarray, y: np.ndarray, sigma2_divisor: str, k_rule):
    """Liu (1993) / Liu-type (2003) from the canonical form, written independently of
    calib.estimators.liu: eigen-decomposition of Z^T Z for the unit-norm columns Z,
    alpha = Lambda^-1 Phi^T Z^T y; with k = 1, d_opt = sum (a^2 - s2)/(l+1)^2 /
    sum (s2 + l a^2)/(l (l+1)^2) as R's liureg/lrmest compute it; alpha_L = (l + d)/(l + k) a."""
    z = x / np.linalg.norm(x, axis=0)
    n, m = z.shape
    lam, phi = np.linalg.eigh(z.T @ z)
    alpha = (phi.T @ z.T @ y) / lam
    resid = y - z @ (phi @ alpha)
    s2 = resid @ resid / (n - m if sigma2_divisor == "unbiased" else n)
    k = m * s2 / (alpha @ alpha) if k_rule == "hkb" else 1.0
    d = np.sum((k * alpha**2 - s2) / (lam + k) ** 2) / np.sum(
        (s2 + lam * alpha**2) / (lam * (lam + k) ** 2)
    )
    d = min(max(d, 0.0), k)
    alpha_l = (lam + d) / (lam + k) * alpha
    return (phi @ alpha_l) / np.linalg.norm(x, axis=0), d


@pytest.mark.parametrize("k_rule", [1.0, "hkb"])
@pytest.mark.parametrize("rule", ["unbiased", "paper"])
def test_liu_matches_independent_derivation_on_hald(rule, k_rule):
    est = Liu(sigma2_rule=rule, k=k_rule).fit(HALD_X, HALD_Y)
    x_ref, d_ref = liu_reference(HALD_X, HALD_Y, rule, k_rule)
    assert est.bias_parameter == pytest.approx(d_ref, rel=1e-10)
    np.testing.assert_allclose(est.x, x_ref, rtol=1e-10)


@pytest.mark.parametrize("k", [1.0, 0.01])
def test_optimal_d_minimises_the_mse(k):
    rng = np.random.default_rng(0)
    lam = np.sort(rng.uniform(1e-3, 5, 8))
    alpha = rng.normal(size=8)
    s2 = 0.3
    d = float(liu_d_optimal(lam, alpha, s2, k))
    best = minimize_scalar(
        lambda t: liu_mse(lam, alpha, s2, t, k), bounds=(-5, 5), method="bounded"
    )
    assert d == pytest.approx(best.x, abs=1e-5)
    assert liu_mse(lam, alpha, s2, d, k) <= liu_mse(lam, alpha, s2, k, k)  # d = k is OLS


def _problem(seed: int = 1, n: int = 60, m: int = 6, collinear: float = 1e-3):
    rng = np.random.default_rng(seed)
    h = rng.normal(size=(n, m))
    h[:, -1] = h[:, 0] + collinear * rng.normal(size=n)  # nearly collinear pair
    h *= np.array([1.0, 1e3, 1e-3, 57.3, 1.0, 1.0])  # mixed units
    x = rng.normal(size=m) / np.array([1.0, 1e3, 1e-3, 57.3, 1.0, 1.0])
    return h, x, rng


def test_ols_equals_lstsq_and_exact_without_noise():
    h, x, rng = _problem()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    est = OLS().fit(h, y)
    np.testing.assert_allclose(est.x, np.linalg.lstsq(h, y, rcond=None)[0], rtol=1e-8)
    cov = est.sigma2 * np.linalg.inv(h.T @ h)
    np.testing.assert_allclose(est.covariance, cov, rtol=1e-6)
    np.testing.assert_allclose(OLS().fit(h, h @ x).x, x, rtol=1e-9)


def test_liu_limits_and_clipping():
    h, x, rng = _problem()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    np.testing.assert_allclose(Liu(d=1.0, k=1.0).fit(h, y).x, OLS().fit(h, y).x, rtol=1e-10)
    # hardly any noise: the optimal d tends to k, i.e. to OLS
    est = Liu(k=1.0).fit(h, h @ x + 1e-12 * rng.normal(size=h.shape[0]))
    assert est.bias_parameter == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(est.x, x, rtol=1e-6)


def test_liu_clips_d_outside_its_interval(monkeypatch):
    import calib.estimators.liu as liu_module

    h, x, rng = _problem()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    monkeypatch.setattr(liu_module, "liu_d_optimal", lambda *a, **k: np.float64(-0.4))
    est = Liu(k=1.0).fit(h, y)
    assert est.bias_parameter == 0.0
    assert "-0.4" in est.notes[0] and "clipped" in est.notes[0]
    ridge_like = Ridge(k=1.0).fit(h, y)  # d = 0 is ridge with the same k
    np.testing.assert_allclose(est.x, ridge_like.x, rtol=1e-10)


def test_ridge_hkb_gcv_and_limit():
    h, x, rng = _problem()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    np.testing.assert_allclose(Ridge(k=1e-14).fit(h, y).x, OLS().fit(h, y).x, rtol=1e-6)
    ols = OLS().fit(h, y)
    hs = h / np.linalg.norm(h, axis=0)
    b = np.linalg.lstsq(hs, y, rcond=None)[0]
    k_hkb = h.shape[1] * ols.sigma2 / (b @ b)
    assert Ridge().fit(h, y).bias_parameter == pytest.approx(k_hkb, rel=1e-10)
    u, s, _ = np.linalg.svd(hs, full_matrices=False)
    uty = u.T @ y
    out = y @ y - uty @ uty
    grid = np.logspace(-12, 2, 4000) * s[0] ** 2
    scores = [gcv_score(s, uty, out, h.shape[0], k) for k in grid]
    k_gcv = Ridge(rule="gcv").fit(h, y).bias_parameter
    assert gcv_score(s, uty, out, h.shape[0], k_gcv) <= min(scores) * (1 + 1e-6)


def test_pcr_all_components_is_ols_and_fewer_stay_in_the_subspace():
    h, x, rng = _problem()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    np.testing.assert_allclose(PCR(n_components=6).fit(h, y).x, OLS().fit(h, y).x, rtol=1e-9)
    est = PCR(n_components=4).fit(h, y)
    hs_scale = np.linalg.norm(h, axis=0)
    _, _, vt = np.linalg.svd(h / hs_scale, full_matrices=False)
    b = est.x * hs_scale
    assert np.linalg.norm(vt[4:] @ b) < 1e-10 * np.linalg.norm(b)


@pytest.mark.parametrize("name", ["ols", "liu", "ridge", "pcr"])
def test_units_do_not_change_predictions(name):
    h, x, rng = _problem()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    scaled = h.copy()
    scaled[:, 1] *= 1000.0
    p1 = h @ make_estimator(name).fit(h, y).x
    p2 = scaled @ make_estimator(name).fit(scaled, y).x
    np.testing.assert_allclose(p1, p2, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", ["ols", "liu", "ridge", "pcr"])
def test_fit_many_equals_loop(name):
    h, x, rng = _problem()
    ys = h @ x + 1e-3 * rng.normal(size=(5, h.shape[0]))
    many = make_estimator(name).fit_many(h, ys)
    loop = np.array([make_estimator(name).fit(h, y).x for y in ys])
    np.testing.assert_allclose(many, loop, rtol=1e-10, atol=1e-14)


def test_monte_carlo_liu_spreads_less_and_ols_covariance_holds():
    h, x, rng = _problem(collinear=1e-4)
    sigma = 1e-2
    ys = h @ x + sigma * rng.normal(size=(2000, h.shape[0]))
    ols = OLS().fit_many(h, ys)
    liu = Liu().fit_many(h, ys)
    assert np.sum(liu.var(axis=0)) < np.sum(ols.var(axis=0))
    analytic = sigma**2 * np.linalg.inv(h.T @ h)
    np.testing.assert_allclose(np.diag(np.cov(ols.T)), np.diag(analytic), rtol=0.1)


def test_bad_input_names_the_cause():
    h, x, _ = _problem()
    y = h @ x
    bad = h.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        OLS().fit(bad, y)
    with pytest.raises(ValueError, match="NaN"):
        OLS().fit(h, np.full_like(y, np.nan))
    with pytest.raises(ValueError, match="5 equations for 6 unknowns"):
        OLS().fit(h[:5], y[:5])
    zero = h.copy()
    zero[:, 2] = 0
    with pytest.raises(ValueError, match=r"column\(s\) \[2\]"):
        Liu().fit(zero, y)
    deficient = h.copy()
    deficient[:, 3] = deficient[:, 0] * 2
    with pytest.raises(ValueError, match="rank deficient"):
        Ridge().fit(deficient, y)
    with pytest.raises(ValueError, match="unknown estimator 'lasso'"):
        make_estimator("lasso")
