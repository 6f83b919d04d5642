"""The loop refit's end: standard errors from the SVD, and the Gauss-Newton polish."""

import numpy as np

from calib.loop.fit import gauss_newton_polish, std_errors


def test_std_errors_equal_the_normal_equations_on_a_well_conditioned_jacobian():
    rng = np.random.default_rng(3)
    jac = rng.standard_normal((60, 5)) * np.array([1.0, 1e3, 1e-3, 2.0, 5.0])
    r = rng.standard_normal(60)
    ref = np.sqrt(np.diag(float(r @ r) / 55 * np.linalg.inv(jac.T @ jac)))
    np.testing.assert_allclose(std_errors(r, jac), ref, rtol=1e-12)


def test_polish_reaches_the_same_minimum_from_nearby_starts():
    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 1.0, 80)
    y = 2.0 * np.exp(-1.3 * t) + 0.5 + 1e-3 * rng.standard_normal(t.size)

    def residual(z):
        return y - (z[0] * np.exp(-z[1] * t) + z[2]), None

    def jacobian(z, _state):
        e = np.exp(-z[1] * t)
        return -np.column_stack([e, -z[0] * t * e, np.ones_like(t)])

    ends = []
    for start in ([2.0, 1.3, 0.5], [2.0 + 1e-6, 1.3 - 1e-6, 0.5]):
        z = np.array(start)
        r, _ = residual(z)
        z, r, jac, steps = gauss_newton_polish(residual, jacobian, z, r, jacobian(z, None))
        assert 1 <= steps < 10
        np.testing.assert_allclose(jac.T @ r, 0.0, atol=1e-12)  # the normal equations hold
        ends.append(z)
    np.testing.assert_allclose(ends[0], ends[1], rtol=1e-12)


def test_polish_refuses_a_step_that_raises_the_cost():
    """Newton on atan overshoots from |z| > 1.39: the polish keeps the start."""

    def residual(z):
        return np.arctan(z), None

    def jacobian(z, _state):
        return (1.0 / (1.0 + z**2))[:, None]

    z0 = np.array([2.0])
    r0, _ = residual(z0)
    z, r, _, steps = gauss_newton_polish(residual, jacobian, z0, r0, jacobian(z0, None))
    assert steps == 0
    np.testing.assert_array_equal(z, z0)
    np.testing.assert_array_equal(r, r0)
