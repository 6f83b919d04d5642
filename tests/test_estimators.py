"""Linear estimators of dp = H dchi + eps (OLS, Liu, ridge, PCR): numbers against references
computed here independently of calib.estimators."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

import calib.estimators.liu as liu_module
from calib.estimators.linear import scale_columns
from calib.estimators.liu import Liu, liu_d_optimal, liu_mse
from calib.estimators.ols import OLS
from calib.estimators.pcr import PCR
from calib.estimators.registry import ESTIMATORS, make_estimator
from calib.estimators.ridge import Ridge

# Hald (1952) cement data, from Woods, Steinour & Starke (1932): heat of hardening against
# four clinker compounds; the classic collinear example of the ridge and Liu (1993)
# literature. Used here without intercept.
HALD_X = np.array(
    [[7, 26, 6, 60], [1, 29, 15, 52], [11, 56, 8, 20], [11, 31, 8, 47], [7, 52, 6, 33],
     [11, 55, 9, 22], [3, 71, 17, 6], [1, 31, 22, 44], [2, 54, 18, 22], [21, 47, 4, 26],
     [1, 40, 23, 34], [11, 66, 9, 12], [10, 68, 8, 12]], dtype=float)  # fmt: skip
HALD_Y = np.array(
    [78.5, 74.3, 104.3, 87.6, 95.9, 109.2, 102.7, 72.5, 93.1, 115.9, 83.8, 113.3, 109.4]
)

# Every estimator and its main options, as a scenario file could ask for them.
VARIANTS = {
    "ols": ("ols", {}),
    "liu": ("liu", {}),
    "liu_paper": ("liu", {"k": 1.0, "sigma2_rule": "paper"}),
    "liu_k1": ("liu", {"k": 1.0}),
    "liu_fixed_d": ("liu", {"k": 1.0, "d": 0.4}),
    "ridge": ("ridge", {}),
    "ridge_gcv": ("ridge", {"rule": "gcv"}),
    "ridge_fixed": ("ridge", {"k": 0.05}),
    "pcr": ("pcr", {}),
    "pcr_3": ("pcr", {"n_components": 3}),
}
UNITS = np.array([1.0, 1.0, 1e-3, 1e-3, 1.0, 57.3, 1.0, 1e3])  # mm, rad, ... per column


def calibration_like(seed=3, n=150, collinear=1e-3, units=UNITS):
    """An ill-conditioned problem with mixed units: columns 0 and 6 nearly collinear."""
    rng = np.random.default_rng(seed)
    m = units.size
    base = rng.normal(size=(n, m))
    base[:, 6] = base[:, 0] + collinear * rng.normal(size=n)
    h = base * units
    x = rng.normal(size=m) / units
    return h, x, rng


def canonical(x, y):
    """Unit-norm columns Z, eigen-decomposition of Z^T Z and OLS in canonical form."""
    norms = np.linalg.norm(x, axis=0)
    z = x / norms
    lam, phi = np.linalg.eigh(z.T @ z)
    alpha = (phi.T @ z.T @ y) / lam
    return z, norms, lam, phi, alpha


def liu_reference(x, y, sigma2_rule="unbiased", k=1.0):
    """Liu (1993) from its canonical definition, alpha_L = (lambda + d)/(lambda + k) alpha,
    with d_opt = sum (k a^2 - s2)/(l + k)^2 / sum (s2 + l a^2)/(l (l + k)^2) as R's liureg and
    lrmest compute it (k = 1), clipped to [0, k]; k = "hkb" is m s2 / |alpha|^2."""
    z, norms, lam, phi, alpha = canonical(x, y)
    n, m = z.shape
    resid = y - z @ (phi @ alpha)
    s2 = resid @ resid / (n if sigma2_rule == "paper" else n - m)
    k = m * s2 / (alpha @ alpha) if k == "hkb" else k
    d = np.sum((k * alpha**2 - s2) / (lam + k) ** 2) / np.sum(
        (s2 + lam * alpha**2) / (lam * (lam + k) ** 2)
    )
    d = min(max(d, 0.0), k)
    return phi @ ((lam + d) / (lam + k) * alpha) / norms, d, s2, k


# --- OLS ------------------------------------------------------------------------------------


def test_ols_equals_lstsq_on_the_unscaled_problem():
    h, x, rng = calibration_like()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    est = OLS().fit(h, y)
    ref = np.linalg.lstsq(h, y, rcond=None)[0]
    # Two factorisations agree to rounding scaled by the condition number, whatever BLAS kernel
    # or thread count ran them; compare in norm, not element by element.
    assert np.linalg.norm(est.x - ref) <= 1e-9 * np.linalg.norm(ref)
    np.testing.assert_allclose(est.linear_map @ y, est.x, rtol=1e-12)


def test_ols_recovers_noise_free_parameters_exactly():
    h, x, _ = calibration_like()
    est = OLS().fit(h, h @ x)
    np.testing.assert_allclose(est.x, x, rtol=1e-9)
    assert est.sigma2 < 1e-25


def test_ols_covariance_is_sigma2_inverse_normal_matrix():
    h, x, rng = calibration_like(collinear=0.1)
    y = h @ x + 1e-2 * rng.normal(size=h.shape[0])
    est = OLS().fit(h, y)
    resid = y - h @ np.linalg.lstsq(h, y, rcond=None)[0]
    assert est.sigma2 == pytest.approx(resid @ resid / (h.shape[0] - h.shape[1]), rel=1e-9)
    cov = est.sigma2 * np.linalg.inv(h.T @ h)
    np.testing.assert_allclose(est.covariance, cov, rtol=1e-8)
    np.testing.assert_allclose(est.std_errors, np.sqrt(np.diag(cov)), rtol=1e-8)
    given = OLS().fit(h, y, sigma2=4e-4)
    assert given.sigma2 == 4e-4
    np.testing.assert_allclose(given.covariance, 4e-4 * np.linalg.inv(h.T @ h), rtol=1e-8)


# --- Liu ------------------------------------------------------------------------------------


@pytest.mark.parametrize("rule", ["unbiased", "paper"])
@pytest.mark.parametrize("k", [1.0, "hkb"])
def test_liu_matches_the_canonical_definition_on_hald(rule, k):
    est = Liu(k=k, sigma2_rule=rule).fit(HALD_X, HALD_Y)
    x_ref, d_ref, s2_ref, k_ref = liu_reference(HALD_X, HALD_Y, rule, k)
    assert est.sigma2 == pytest.approx(s2_ref, rel=1e-10)
    assert est.scale_parameter == pytest.approx(k_ref, rel=1e-10)
    assert est.bias_parameter == pytest.approx(d_ref, rel=1e-10, abs=1e-14)
    np.testing.assert_allclose(est.x, x_ref, rtol=1e-10)


def test_liu_on_hald_is_eq_11_with_an_interior_d():
    """The paper's form (Z^T Z + I)^-1 (Z^T y + d b_OLS) and its map A for the covariance."""
    est = Liu(k=1.0).fit(HALD_X, HALD_Y)
    d = est.bias_parameter
    assert 0.98 < d < 0.99  # Eq. 14 on Hald: inside (0, 1), no clipping
    assert est.notes == ("k = 1 (given)",)
    z, norms, *_ = canonical(HALD_X, HALD_Y)
    g = z.T @ z
    b_ols = np.linalg.solve(g, z.T @ HALD_Y)
    b_liu = np.linalg.solve(g + np.eye(4), z.T @ HALD_Y + d * b_ols)
    np.testing.assert_allclose(est.x, b_liu / norms, rtol=1e-10)
    a = np.linalg.solve(g + np.eye(4), z.T + d * np.linalg.solve(g, z.T))
    cov = est.sigma2 * (a @ a.T) / np.outer(norms, norms)
    np.testing.assert_allclose(est.covariance, cov, rtol=1e-9)
    np.testing.assert_allclose(est.std_errors, np.sqrt(np.diag(cov)), rtol=1e-9)
    assert np.all(est.std_errors < OLS().fit(HALD_X, HALD_Y, sigma2=est.sigma2).std_errors)


def _mse_inputs():
    _, _, lam, _, alpha = canonical(HALD_X, HALD_Y)
    return lam, alpha, liu_reference(HALD_X, HALD_Y)[2]


@pytest.mark.parametrize("k", [1.0, 0.01])
def test_eq_14_minimises_eq_13(k):
    lam, alpha, s2 = _mse_inputs()
    d = float(liu_d_optimal(lam, alpha, s2, k))
    grid = np.linspace(-2.0, 2.0, 400_001)
    mse = [liu_mse(lam, alpha, s2, t, k) for t in grid[::100]]
    assert abs(d - grid[::100][int(np.argmin(mse))]) <= 1e-3
    best = minimize_scalar(
        lambda t: liu_mse(lam, alpha, s2, t, k), bounds=(-2, 2), method="bounded",
        options={"xatol": 1e-10},
    )  # fmt: skip
    assert d == pytest.approx(best.x, abs=1e-6)
    assert liu_mse(lam, alpha, s2, d, k) <= best.fun * (1 + 1e-12)
    assert liu_mse(lam, alpha, s2, d, k) <= liu_mse(lam, alpha, s2, k, k)  # d = k is OLS
    # the MSE at d = k is the OLS variance sigma^2 sum 1 / lambda
    assert liu_mse(lam, alpha, s2, k, k) == pytest.approx(s2 * np.sum(1 / lam), rel=1e-12)


def test_eq_14_never_exceeds_one_when_there_is_noise():
    """d - k = -s2 sum 1/(l (l + k)) / den < 0: only the lower clip can act on real data."""
    rng = np.random.default_rng(7)
    lam = rng.uniform(1e-4, 5, size=(500, 6))
    alpha = rng.normal(size=(500, 6)) * rng.uniform(0, 3, size=(500, 1))
    d = np.array([liu_d_optimal(lam[i], alpha[i], 0.2) for i in range(500)])
    assert np.all(d < 1.0)


def test_liu_with_d_one_is_ols():
    h, x, rng = calibration_like()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    np.testing.assert_allclose(Liu(d=1.0, k=1.0).fit(h, y).x, OLS().fit(h, y).x, rtol=1e-10)


def _clipped_to_zero_case():
    """Pure noise on a well-conditioned H: Eq. 14 gives a negative d for this seed."""
    rng = np.random.default_rng(11)
    h = rng.normal(size=(40, 5)) * np.array([1.0, 1e2, 1e-2, 1.0, 3.0])
    y = rng.normal(size=40)
    return h, y


def test_liu_clips_a_negative_d_to_zero_the_ridge_like_estimate():
    h, y = _clipped_to_zero_case()
    est = Liu(k=1.0).fit(h, y)
    z, norms, lam, _, alpha = canonical(h, y)
    s2 = est.sigma2
    d_raw = np.sum((alpha**2 - s2) / (lam + 1) ** 2) / np.sum(
        (s2 + lam * alpha**2) / (lam * (lam + 1) ** 2)
    )
    assert d_raw < 0
    assert est.bias_parameter == 0.0
    assert f"{d_raw:.4g}" in est.notes[0] and "outside (0, 1)" in est.notes[0]
    assert "clipped to 0" in est.notes[0]
    ridge_like = np.linalg.solve(z.T @ z + np.eye(5), z.T @ y) / norms
    np.testing.assert_allclose(est.x, ridge_like, rtol=1e-10)


def test_liu_clips_a_d_above_one_to_ols(monkeypatch):
    h, x, rng = calibration_like()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    monkeypatch.setattr(liu_module, "liu_d_optimal", lambda *a, **kw: np.float64(1.37))
    est = Liu(k=1.0).fit(h, y)
    assert est.bias_parameter == 1.0
    assert "1.37" in est.notes[0] and "clipped to 1 (OLS)" in est.notes[0]
    np.testing.assert_allclose(est.x, OLS().fit(h, y).x, rtol=1e-10)


# --- ridge and PCR --------------------------------------------------------------------------


def test_ridge_tends_to_ols_and_hkb_k_is_its_formula():
    h, x, rng = calibration_like()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    ols = OLS().fit(h, y)
    np.testing.assert_allclose(Ridge(k=1e-13).fit(h, y).x, ols.x, rtol=1e-6)
    b = np.linalg.lstsq(h / np.linalg.norm(h, axis=0), y, rcond=None)[0]
    est = Ridge().fit(h, y)
    assert est.bias_parameter == pytest.approx(h.shape[1] * ols.sigma2 / (b @ b), rel=1e-10)
    z, norms, *_ = canonical(h, y)
    ref = np.linalg.solve(z.T @ z + est.bias_parameter * np.eye(h.shape[1]), z.T @ y) / norms
    np.testing.assert_allclose(est.x, ref, rtol=1e-8)


def test_ridge_gcv_finds_the_minimum_of_a_dense_grid():
    h, x, rng = calibration_like(collinear=1e-4)
    y = h @ x + 0.3 * rng.normal(size=h.shape[0])
    z, _, lam, _, _ = canonical(h, y)
    n = h.shape[0]

    def gcv(k):  # straight from the definition, hat matrix and all
        s = z @ np.linalg.solve(z.T @ z + k * np.eye(z.shape[1]), z.T)
        r = y - s @ y
        return n * (r @ r) / (n - np.trace(s)) ** 2

    grid = np.logspace(-12, 2, 3000) * lam.max()
    scores = np.array([gcv(k) for k in grid])
    k_gcv = Ridge(rule="gcv").fit(h, y).bias_parameter
    i = int(np.argmin(scores))
    assert 0 < i < grid.size - 1  # an interior minimum
    assert grid[i - 1] <= k_gcv <= grid[i + 1]
    assert gcv(k_gcv) <= scores[i] * (1 + 1e-9)


def test_pcr_with_every_component_is_ols_and_fewer_stay_in_the_kept_subspace():
    h, x, rng = calibration_like()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    m = h.shape[1]
    np.testing.assert_allclose(PCR(n_components=m).fit(h, y).x, OLS().fit(h, y).x, rtol=1e-9)
    est = PCR(n_components=5).fit(h, y)
    assert est.bias_parameter == 5.0
    _, norms, lam, phi, _ = canonical(h, y)
    dropped = phi[:, np.argsort(lam)[: m - 5]]  # eigenvectors of the 3 smallest eigenvalues
    b = est.x * norms
    assert np.linalg.norm(dropped.T @ b) < 1e-12 * np.linalg.norm(b)


def test_pcr_default_drops_only_eigenvalues_below_rtol():
    h, x, rng = calibration_like(collinear=1e-4)  # lambda_min / lambda_max ~ 1e-9
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    _, _, lam, _, _ = canonical(h, y)
    est = PCR().fit(h, y)
    assert est.bias_parameter == np.sum(lam > 1e-6 * lam.max()) == h.shape[1] - 1
    assert "kept 7 of 8" in est.notes[0]
    assert PCR(rtol=1e-12).fit(h, y).bias_parameter == h.shape[1]


# --- every estimator ------------------------------------------------------------------------


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_units_do_not_change_predictions(variant):
    name, opts = VARIANTS[variant]
    h, x, rng = calibration_like()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    h_mm = h.copy()
    h_mm[:, 1] *= 1000.0  # the column in other units; the true x[1] becomes x[1] / 1000
    est, est_mm = make_estimator(name, **opts).fit(h, y), make_estimator(name, **opts).fit(h_mm, y)
    p, p_mm = h @ est.x, h_mm @ est_mm.x
    np.testing.assert_allclose(p_mm, p, rtol=1e-9, atol=1e-9 * np.abs(p).max())
    assert est_mm.x[1] == pytest.approx(est.x[1] / 1000.0, rel=1e-9)
    assert est_mm.std_errors[1] == pytest.approx(est.std_errors[1] / 1000.0, rel=1e-9)


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_fit_many_equals_a_loop_of_fit(variant):
    name, opts = VARIANTS[variant]
    h, x, rng = calibration_like()
    ys = h @ x + 1e-3 * rng.normal(size=(20, h.shape[0]))
    many = make_estimator(name, **opts).fit_many(h, ys)
    loop = np.array([make_estimator(name, **opts).fit(h, y).x for y in ys])
    assert many.shape == (20, h.shape[1])
    np.testing.assert_allclose(many, loop, rtol=1e-12, atol=1e-12 * np.abs(loop).max())


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_estimate_is_its_linear_map_and_covariance_its_square(variant):
    name, opts = VARIANTS[variant]
    h, x, rng = calibration_like()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    est = make_estimator(name, **opts).fit(h, y)
    a = est.linear_map
    assert est.method == name and a.shape == (h.shape[1], h.shape[0])
    np.testing.assert_allclose(a @ y, est.x, rtol=1e-9, atol=1e-12 * np.abs(est.x).max())
    np.testing.assert_allclose(est.covariance, est.sigma2 * a @ a.T, rtol=1e-9, atol=0)


def test_monte_carlo_liu_spreads_less_and_ols_covariance_holds():
    h, x, rng = calibration_like(collinear=1e-3)  # condition number of Hs ~ 2e3
    sigma = 5e-3
    ys = h @ x + sigma * rng.normal(size=(2000, h.shape[0]))
    ols = OLS().fit_many(h, ys)
    analytic = sigma**2 * np.linalg.inv(h.T @ h)
    empirical = np.cov(ols.T)
    np.testing.assert_allclose(np.diag(empirical), np.diag(analytic), rtol=0.1)
    assert np.linalg.norm(empirical - analytic) < 0.1 * np.linalg.norm(analytic)
    norms2 = np.linalg.norm(h, axis=0) ** 2  # variances in scaled (unit-free) terms
    liu = Liu().fit_many(h, ys)  # d, k and sigma^2 re-estimated in every run
    assert np.sum(liu.var(axis=0)) < 0.8 * np.sum(ols.var(axis=0))
    assert np.sum(liu.var(axis=0) * norms2) < 0.7 * np.sum(ols.var(axis=0) * norms2)
    # the paper's k = 1: less spread on the scaled problem (its own metric); in the original
    # units its run-to-run d moves the well-determined parameters too (see liu.py)
    liu_k1 = Liu(k=1.0).fit_many(h, ys)
    assert np.sum(liu_k1.var(axis=0) * norms2) < 0.8 * np.sum(ols.var(axis=0) * norms2)


@pytest.mark.parametrize("d", [0.0, 0.3, 1.0])
def test_liu_covariance_never_exceeds_ols_for_a_fixed_d(d):
    """0 <= d <= 1 gives filter factors (l + d)/(l + 1) <= 1: cov_OLS - cov_Liu is PSD."""
    h, x, rng = calibration_like()
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    ols = OLS().fit(h, y)
    liu = Liu(d=d, k=1.0).fit(h, y, sigma2=ols.sigma2)
    scale = np.linalg.norm(h, axis=0)
    gap = (ols.covariance - liu.covariance) * np.outer(scale, scale)
    assert np.linalg.eigvalsh(gap).min() >= -1e-12 * np.abs(gap).max()


# --- bad input ------------------------------------------------------------------------------


def test_registry_names_the_estimators():
    assert sorted(ESTIMATORS) == ["liu", "liu_cv", "liu_paper", "ols", "pcr", "ridge"]
    assert isinstance(make_estimator("liu", k=1.0), Liu)
    with pytest.raises(
        ValueError, match=r"unknown estimator 'lasso'.*'liu', 'liu_cv', 'liu_paper', 'ols', 'pcr'"
    ):
        make_estimator("lasso")
    with pytest.raises(ValueError, match=r"bad options.*'ols'"):
        make_estimator("ols", d=0.5)


def test_bad_input_names_the_cause():
    h, x, _ = calibration_like()
    y = h @ x
    bad = h.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="H contains NaN"):
        OLS().fit(bad, y)
    with pytest.raises(ValueError, match="y contain NaN"):
        Liu().fit(h, np.where(np.arange(y.size) == 5, np.inf, y))
    with pytest.raises(ValueError, match="8 equations for 8 unknowns"):
        Ridge().fit(h[:8], y[:8])
    with pytest.raises(ValueError, match=r"column\(s\) \[4\] of H are zero"):
        zero = h.copy()
        zero[:, 4] = 0.0
        PCR().fit(zero, y)
    with pytest.raises(ValueError, match=r"column\(s\) \[4\]"):
        scale_columns(zero)
    deficient = h.copy()
    deficient[:, 5] = 2.0 * deficient[:, 1] - deficient[:, 3]
    with pytest.raises(ValueError, match=r"rank deficient \(rank 7 of 8.*reconstruct"):
        Liu().fit(deficient, y)
    with pytest.raises(ValueError, match="149 entries per draw but H has 150 rows"):
        OLS().fit(h, y[:-1])
    with pytest.raises(ValueError, match="must be a vector"):
        OLS().fit(h, np.vstack([y, y]))
    with pytest.raises(ValueError, match="2-D"):
        OLS().fit(h[:, 0], y)
    with pytest.raises(ValueError, match="sigma2_rule"):
        Liu(sigma2_rule="ml")
    with pytest.raises(ValueError, match="rule must be 'hkb' or 'gcv'"):
        Ridge(rule="lw")
    with pytest.raises(ValueError, match="n_components = 9 exceeds the 8 unknowns"):
        PCR(n_components=9).fit(h, y)
    with pytest.raises(ValueError, match="sigma2 must be"):
        OLS().fit(h, y, sigma2=-1.0)


def test_scale_columns_divides_by_the_column_norms():
    h, _, _ = calibration_like()
    hs, scale = scale_columns(h)
    np.testing.assert_allclose(scale, np.sqrt(np.sum(h**2, axis=0)), rtol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(hs, axis=0), 1.0, rtol=1e-14)


def test_liu_in_the_papers_units_is_eq_11_literally():
    """(H^T H + I)^-1 (H^T y + d b_OLS) with H in mm and deg (or rad), d from Eq. 14, written
    out with explicit inverses; its answer depends on the unit of the angle columns. The noise
    variance is Eq. 13's RSS / n, or RSS / (n - m) when asked for."""
    from calib.estimators.liu import liu_d_optimal
    from calib.estimators.liu_paper_units import LiuPaperUnits

    rng = np.random.default_rng(3)
    is_angle = np.array([False, True, False, True])
    h = rng.normal(size=(40, 4)) * np.where(is_angle, 0.3, 1.0)  # SI: m per m, m per rad
    x_true = np.array([1e-4, 2e-4, -3e-4, 1e-4])
    y = h @ x_true + rng.normal(0, 5e-6, 40)
    out = {}
    for unit, per_rad in (("deg", np.pi / 180), ("rad", 1.0)):
        for rule, dof in (("paper", 40), ("unbiased", 40 - 4)):
            units = np.where(is_angle, 1 / per_rad, 1e3)  # paper units per SI unit
            hp, yp = h * 1e3 / units, y * 1e3
            g = hp.T @ hp
            b_ols = np.linalg.solve(g, hp.T @ yp)
            lam, phi = np.linalg.eigh(g)
            alpha = phi.T @ b_ols
            s2 = np.sum((yp - hp @ b_ols) ** 2) / dof
            d = float(np.clip(liu_d_optimal(lam, alpha[None, :], s2, 1.0)[0], 0, 1))
            expected = np.linalg.solve(g + np.eye(4), hp.T @ yp + d * b_ols) / units
            est = LiuPaperUnits(angle_unit=unit, is_angle=is_angle, sigma2_rule=rule).fit(h, y)
            np.testing.assert_allclose(est.x, expected, rtol=1e-9, atol=1e-15)
            assert est.bias_parameter == pytest.approx(d)
            out[unit, rule] = est.x
    assert not np.allclose(out["deg", "paper"], out["rad", "paper"], rtol=1e-8, atol=0)
    assert not np.allclose(out["deg", "paper"], out["deg", "unbiased"], rtol=1e-8, atol=0)
    with pytest.raises(ValueError, match="which of the H columns are angles"):
        LiuPaperUnits().fit(h, y)
    with pytest.raises(ValueError, match="sigma2_rule"):
        LiuPaperUnits(sigma2_rule="n-1")


def test_paper_units_liu_against_eqs_11_to_14_by_svd():
    """The first paper's Eqs. 11-14 evaluated term by term from the SVD of H in mm and deg:
    Eq. 12's Z = H Phi and Lambda (Phi, lambda from the SVD H = U S V^T: Phi = V, lambda =
    s^2), Eq. 13's sigma^2 = tr(r r^T) / n and alpha_j^2 = (Phi^T b b^T Phi)_jj, Eq. 14's d as
    written (sums over j), Eq. 11 as written; d must come out inside (0, 1), unclipped, for
    the check to be of the formula and not of the clipping. The default of the estimator is
    this reading (sigma^2 = RSS / n)."""
    from calib.estimators.liu_paper_units import LiuPaperUnits

    rng = np.random.default_rng(11)
    n, m = 60, 5
    is_angle = np.array([False, False, True, False, True])
    base = rng.normal(size=(n, m))
    base[:, 3] = base[:, 0] + 0.05 * rng.normal(size=n)  # multicollinear, as the paper's H
    h = base * np.where(is_angle, 0.2, 1.0)  # SI: metres of target per metre or radian
    x_true = np.array([4e-5, -2e-5, 3e-4, 1e-5, -2e-4])  # m and rad
    y = h @ x_true + rng.normal(0, 4e-6, n)  # m

    units = np.where(is_angle, 180.0 / np.pi, 1e3)  # mm per m, deg per rad
    hp, yp = h * 1e3 / units, y * 1e3  # H in mm per (mm or deg), dp in mm
    u, sv, vt = np.linalg.svd(hp, full_matrices=False)
    phi, lam = vt.T, sv**2  # Eq. 12: the eigenvectors and eigenvalues of H^T H
    z = hp @ phi
    np.testing.assert_allclose(z.T @ z, np.diag(lam), atol=1e-9 * lam.max())
    b_ols = phi @ ((u.T @ yp) / sv)  # OLS, from the SVD
    r = yp - hp @ b_ols
    sigma2 = np.trace(np.outer(r, r)) / n  # Eq. 13
    alpha2 = np.diag(phi.T @ np.outer(b_ols, b_ols) @ phi)  # Eq. 13's alpha_j^2
    d = sum((alpha2[i] - sigma2) / (lam[i] + 1) ** 2 for i in range(m)) / sum(
        (sigma2 + lam[i] * alpha2[i]) / (lam[i] * (lam[i] + 1) ** 2) for i in range(m)
    )  # Eq. 14
    assert 0.0 < d < 1.0
    chi_l = np.linalg.inv(hp.T @ hp + np.eye(m)) @ (hp.T @ yp + d * b_ols)  # Eq. 11, mm / deg

    est = LiuPaperUnits(angle_unit="deg", is_angle=is_angle).fit(h, y)
    assert est.bias_parameter == pytest.approx(d, rel=1e-10)
    assert est.scale_parameter == 1.0
    assert est.sigma2 == pytest.approx(sigma2 * 1e-6, rel=1e-10)  # m^2
    np.testing.assert_allclose(est.x * units, chi_l, rtol=1e-9, atol=1e-12 * np.abs(chi_l).max())
    # the same through the estimator's batched paths
    np.testing.assert_allclose(
        LiuPaperUnits(angle_unit="deg", is_angle=is_angle).fit_many(h, y[None, :])[0] * units,
        chi_l,
        rtol=1e-9,
    )
    assert "sigma^2 = RSS / n (Eq. 13)" in est.notes


def test_draws_give_each_estimator_its_fit_many():
    """The Monte Carlo's shared products (calib.estimators.linear.draws): every estimator that
    reads them gives what its fit_many gives on the measurement vectors y0 + noise."""
    from calib.estimators.linear import draws, prepare
    from calib.estimators.liu_paper_units import LiuPaperUnits

    h, x, rng = calibration_like()
    is_angle = np.array([False, True, False, True, False, True, False, False])
    y0 = h @ x + 1e-3 * rng.normal(size=h.shape[0])  # not in the column space of H
    noise = 1e-3 * rng.normal(size=(50, h.shape[0]))
    ys = y0 + noise
    shared = draws(h, y0, noise, chunk=7)  # several chunks, the last one short
    prob = prepare(h)
    np.testing.assert_allclose(shared.yu, ys @ prob.u, rtol=0, atol=1e-13 * np.abs(ys).max())
    np.testing.assert_allclose(shared.rss, prob.ols_rss(ys), rtol=1e-12)
    for est in (
        OLS(),
        Liu(),
        Liu(k=1.0),
        Liu(k=1.0, sigma2_rule="paper"),
        Liu(k=1.0, d=0.4),
        LiuPaperUnits(angle_unit="deg", is_angle=is_angle),
        LiuPaperUnits(angle_unit="rad", is_angle=is_angle),
    ):
        many = est.fit_many(h, ys)
        np.testing.assert_allclose(
            est.fit_draws(shared), many, rtol=1e-12, atol=1e-12 * np.abs(many).max()
        )
    with pytest.raises(ValueError, match="noise must be"):
        draws(h, y0, noise[:, :-1])


def test_paper_units_liu_states_its_variance_and_covariance_in_si():
    """sigma^2 in m^2 like every estimate, and the covariance sigma^2 A A^T of its linear map
    (a variance of mm^2 taken for m^2 made the standard errors 1000 times too large)."""
    from calib.estimators.liu_paper_units import LiuPaperUnits

    h, x, rng = calibration_like()
    is_angle = np.array([False, True, False, True, False, True, False, False])
    y = h @ x + 1e-3 * rng.normal(size=h.shape[0])
    est = LiuPaperUnits(angle_unit="deg", is_angle=is_angle).fit(h, y)
    ols = OLS().fit(h, y)
    rss = np.sum((y - h @ ols.x) ** 2)
    assert est.sigma2 == pytest.approx(rss / h.shape[0], rel=1e-10)
    a = est.linear_map
    np.testing.assert_allclose(est.covariance, est.sigma2 * a @ a.T, rtol=1e-9, atol=1e-30)
    np.testing.assert_allclose(a @ y, est.x, rtol=1e-9, atol=1e-12 * np.abs(est.x).max())
