import numpy as np
import pytest

from twin.rigid_fit import RigidFitError, fit_residuals, fit_rigid_transform
from twin.rotations import matrix_from_rotvec, rotation_angle


def _random_pose(rng: np.random.Generator, batch: tuple[int, ...] = ()) -> tuple:
    rotvec = rng.normal(size=(*batch, 3))
    rotvec *= (rng.uniform(0.0, np.pi, size=batch) / np.linalg.norm(rotvec, axis=-1))[..., None]
    return matrix_from_rotvec(rotvec), rng.uniform(-1.0, 1.0, size=(*batch, 3))


def _apply(R: np.ndarray, p: np.ndarray, local: np.ndarray) -> np.ndarray:
    return np.einsum("...ij,nj->...ni", R, local) + p[..., None, :]


@pytest.mark.parametrize("n", [3, 4, 7, 20])
def test_exact_recovery(n: int) -> None:
    rng = np.random.default_rng(1234 + n)
    for _ in range(20):
        local = rng.uniform(-0.2, 0.2, size=(n, 3))
        R, p = _random_pose(rng)
        R_fit, p_fit = fit_rigid_transform(local, _apply(R, p, local))
        assert np.max(np.abs(R_fit - R)) < 1e-12
        assert np.max(np.abs(p_fit - p)) < 1e-12
        assert np.linalg.det(R_fit) == pytest.approx(1.0, abs=1e-12)


def test_exact_recovery_coplanar_points() -> None:
    # four coplanar points: the cross-covariance has rank 2, the sign guard picks det +1
    rng = np.random.default_rng(7)
    local = np.array([[0.1, 0.0, 0.0], [-0.1, 0.05, 0.0], [0.0, -0.12, 0.0], [0.03, 0.08, 0.0]])
    R, p = _random_pose(rng, (50,))
    R_fit, p_fit = fit_rigid_transform(local, _apply(R, p, local))
    assert np.max(np.abs(R_fit - R)) < 1e-12
    assert np.max(np.abs(p_fit - p)) < 1e-12


def test_batched_equals_looped() -> None:
    rng = np.random.default_rng(42)
    local = rng.uniform(-0.1, 0.1, size=(5, 3))
    R, p = _random_pose(rng, (4, 6))
    measured = _apply(R, p, local) + rng.normal(scale=1e-4, size=(4, 6, 5, 3))
    R_b, p_b = fit_rigid_transform(local, measured)
    assert R_b.shape == (4, 6, 3, 3)
    assert p_b.shape == (4, 6, 3)
    for idx in np.ndindex(4, 6):
        R_i, p_i = fit_rigid_transform(local, measured[idx])
        np.testing.assert_allclose(R_b[idx], R_i, atol=1e-14)
        np.testing.assert_allclose(p_b[idx], p_i, atol=1e-14)


def test_reflection_gives_proper_rotation() -> None:
    rng = np.random.default_rng(3)
    local = rng.uniform(-0.1, 0.1, size=(6, 3))
    mirrored = local * np.array([-1.0, 1.0, 1.0])
    R_fit, _ = fit_rigid_transform(local, mirrored)
    assert np.linalg.det(R_fit) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(R_fit @ R_fit.T, np.eye(3), atol=1e-12)


def test_noise_rms_residual() -> None:
    # E[sum of squared residuals] = sigma^2 * (3N - 6) for isotropic Gaussian noise
    rng = np.random.default_rng(11)
    n, sigma, trials = 6, 20e-6, 4000
    local = rng.uniform(-0.15, 0.15, size=(n, 3))
    R, p = _random_pose(rng, (trials,))
    measured = _apply(R, p, local) + rng.normal(scale=sigma, size=(trials, n, 3))
    R_fit, p_fit = fit_rigid_transform(local, measured)
    res = fit_residuals(local, measured, R_fit, p_fit)
    assert res.shape == (trials, n, 3)
    rms = np.sqrt(np.mean(res**2))
    expected = sigma * np.sqrt((3 * n - 6) / (3 * n))
    assert rms == pytest.approx(expected, rel=0.02)
    # the fit beats the noise: pose errors are of the order of sigma / sqrt(N)
    assert np.sqrt(np.mean((p_fit - p) ** 2)) < sigma
    assert np.sqrt(np.mean(rotation_angle(R_fit @ np.swapaxes(R, -1, -2)) ** 2)) < 1e-3
    # residuals of the true pose equal the injected noise
    np.testing.assert_allclose(
        fit_residuals(local, measured, R, p), measured - _apply(R, p, local), atol=1e-15
    )


def test_weights() -> None:
    rng = np.random.default_rng(5)
    local = rng.uniform(-0.1, 0.1, size=(6, 3))
    R, p = _random_pose(rng)
    measured = _apply(R, p, local)
    measured[5] += 0.05  # outlier
    w = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 0.0])
    R_fit, p_fit = fit_rigid_transform(local, measured, w)
    assert np.max(np.abs(R_fit - R)) < 1e-12
    assert np.max(np.abs(p_fit - p)) < 1e-12
    # scaling all weights changes nothing; per-batch weights broadcast
    noisy = measured[None] + rng.normal(scale=1e-4, size=(3, 6, 3))
    w2 = rng.uniform(0.5, 2.0, size=(3, 6))
    R_a, p_a = fit_rigid_transform(local, noisy, w2)
    R_b, p_b = fit_rigid_transform(local, noisy, 7.0 * w2)
    np.testing.assert_allclose(R_a, R_b, atol=1e-14)
    np.testing.assert_allclose(p_a, p_b, atol=1e-14)
    R_1, p_1 = fit_rigid_transform(local, noisy[1], w2[1])
    np.testing.assert_allclose(R_a[1], R_1, atol=1e-14)
    np.testing.assert_allclose(p_a[1], p_1, atol=1e-14)


def test_collinear_raises() -> None:
    local = np.array([[0.0, 0.0, 0.0], [0.1, 0.1, 0.0], [0.2, 0.2, 0.0], [0.3, 0.3, 0.0]])
    with pytest.raises(RigidFitError, match="collinear"):
        fit_rigid_transform(local, local)
    nearly = local.copy()
    nearly[1, 2] = 1e-9
    with pytest.raises(RigidFitError, match="collinear"):
        fit_rigid_transform(nearly, nearly)
    coincident = np.zeros((4, 3))
    with pytest.raises(RigidFitError, match="collinear or coincident"):
        fit_rigid_transform(coincident, coincident)


def test_too_few_points_raises() -> None:
    local = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])
    with pytest.raises(RigidFitError, match="at least 3 points"):
        fit_rigid_transform(local, local)
    three = np.eye(3)
    with pytest.raises(RigidFitError, match="positive weight"):
        fit_rigid_transform(three, three, [1.0, 1.0, 0.0])


def test_non_finite_raises() -> None:
    local = np.eye(3) * 0.1
    bad = local.copy()
    bad[0, 1] = np.nan
    with pytest.raises(RigidFitError, match="points_measured contains non-finite"):
        fit_rigid_transform(local, bad)
    with pytest.raises(RigidFitError, match="points_local contains non-finite"):
        fit_rigid_transform(bad, local)
    with pytest.raises(RigidFitError, match="weights contain non-finite"):
        fit_rigid_transform(local, local, [1.0, np.inf, 1.0])


def test_shape_mismatch_raises() -> None:
    local = np.eye(4, 3)
    with pytest.raises(RigidFitError, match="points_local has 4"):
        fit_rigid_transform(local, np.zeros((2, 5, 3)))
    with pytest.raises(RigidFitError, match=r"shape \(\.\.\., N, 3\)"):
        fit_rigid_transform(local, np.zeros((4, 2)))
    with pytest.raises(RigidFitError, match="weights"):
        fit_rigid_transform(local, np.zeros((2, 4, 3)), np.ones((3, 4)))
    assert issubclass(RigidFitError, ValueError)
