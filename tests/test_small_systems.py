"""The vectorised small-system solvers (twin.kinematics.small_systems) against numpy.linalg.

On stacks of random well-conditioned and ill-conditioned systems (condition numbers up to
1e8, rows deliberately badly ordered so that static pivots are refused and Householder takes
over) the solutions equal LAPACK's to 1e-12 relative to their size; least squares equals
``numpy.linalg.lstsq``; the pivot order is partial pivoting's.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.kinematics.small_systems import (
    back_substitute,
    eliminate,
    eliminate_static,
    pivot_order,
    solve_dense,
    solve_square,
)


def _stack(rng: np.random.Generator, n: int, rows: int, cols: int, cond: float) -> np.ndarray:
    """(n, rows, cols) matrices with singular values spread log-uniformly over [1/cond, 1]."""
    u = np.linalg.qr(rng.normal(size=(n, rows, rows)))[0]
    v = np.linalg.qr(rng.normal(size=(n, cols, cols)))[0]
    k = min(rows, cols)
    s = np.zeros((n, rows, cols))
    s[:, np.arange(k), np.arange(k)] = np.logspace(0, -np.log10(cond), k)
    return u @ s @ v


def _soa(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[A | B] stacks (n, r, s), (n, r, m) as one (r, s + m, n) array."""
    return np.ascontiguousarray(np.concatenate([a, b], axis=2).transpose(1, 2, 0))


@pytest.mark.parametrize("size", [1, 3, 6])
@pytest.mark.parametrize("cond", [1.0, 1e3, 1e8])
def test_solve_square_equals_lapack(size, cond):
    rng = np.random.default_rng(size * 100 + int(np.log10(cond)))
    a = _stack(rng, 500, size, size, cond)
    b = rng.normal(size=(500, size, 2))
    ref = np.linalg.solve(a, b)
    x = solve_square(_soa(a, b)).transpose(2, 0, 1)
    scale = 1.0 + np.abs(ref).max(axis=(1, 2), keepdims=True)
    # forward error bound: cond * eps, the same for both solvers
    np.testing.assert_allclose(x / scale, ref / scale, rtol=0, atol=max(1e-12, cond * 1e-15))
    if cond == 1.0:
        np.testing.assert_allclose(x, ref, rtol=0, atol=1e-12)


def test_solve_square_refused_pivots_take_householder():
    """Rows ordered so that the first pivot is tiny: every static elimination is refused,
    and the answers are still LAPACK's."""
    rng = np.random.default_rng(3)
    a = _stack(rng, 200, 6, 6, 10.0)
    a[:, 0, 0] = 1e-14
    b = rng.normal(size=(200, 6, 1))
    mat = _soa(a, b)
    assert not np.any(eliminate_static(mat.copy(), 6))
    ref = np.linalg.solve(a, b)
    scale = 1.0 + np.abs(ref).max(axis=(1, 2), keepdims=True)
    x = solve_square(mat).transpose(2, 0, 1)
    np.testing.assert_allclose(x / scale, ref / scale, rtol=0, atol=1e-12)


def test_singular_systems_give_no_finite_answer_silently():
    a = np.zeros((4, 3, 3))
    a[:, 0, 0] = 1.0  # rank 1
    x = solve_square(_soa(a, np.ones((4, 3, 1))))
    assert not np.all(np.isfinite(x))


@pytest.mark.parametrize("cond", [1.0, 1e6])
def test_least_squares_equals_lstsq(cond):
    rng = np.random.default_rng(11)
    a = _stack(rng, 300, 7, 4, cond)
    b = rng.normal(size=(300, 7, 2))
    ref = np.stack([np.linalg.lstsq(ai, bi, rcond=None)[0] for ai, bi in zip(a, b, strict=True)])
    x = solve_dense(_soa(a, b), 4).transpose(2, 0, 1)
    np.testing.assert_allclose(x, ref, rtol=0, atol=max(1e-12, cond * 1e-15) * np.abs(ref).max())


def test_static_elimination_with_good_pivots_equals_lapack():
    rng = np.random.default_rng(5)
    a = _stack(rng, 100, 6, 6, 100.0)
    b = rng.normal(size=(100, 6, 1))
    order = pivot_order(a[0], 6)
    mat = _soa(a[:, order], b[:, order])
    ok = eliminate_static(mat, 6)
    x = back_substitute(mat[:, :6], mat[:, 6:]).transpose(2, 0, 1)
    ref = np.linalg.solve(a, b)
    assert np.mean(ok) > 0.5
    scale = 1.0 + np.abs(ref).max(axis=(1, 2), keepdims=True)
    np.testing.assert_allclose((x / scale)[ok], (ref / scale)[ok], rtol=0, atol=1e-12)


def test_pivot_order_is_partial_pivoting():
    a = np.array([[1.0, 2.0, 0.0], [4.0, 1.0, 1.0], [2.0, 8.0, 3.0]])
    order = pivot_order(a, 3)
    assert order[0] == 1  # largest |a[:, 0]|
    # after eliminating column 0 with row 1, row 2 has the larger second entry
    assert list(order) == [1, 2, 0]


def test_householder_triangularises():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(5, 5, 10))
    r = a.copy()
    eliminate(r, 5)
    assert np.all(r[np.tril_indices(5, -1)] == 0.0)
    # |det| is kept by an orthogonal transformation
    det_a = np.abs(np.linalg.det(a.transpose(2, 0, 1)))
    det_r = np.abs(np.prod(r[np.arange(5), np.arange(5)], axis=0))
    np.testing.assert_allclose(det_r, det_a, rtol=1e-12)
