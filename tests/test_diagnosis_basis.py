"""A training set's projection basis: Q and G+ from one SVD, bit for bit the arithmetic of
numpy's pinv and orthonormal basis, in the same memory layout (a BLAS product's order of sums
follows it), whether G+ is kept or made again from the factors when asked."""

from __future__ import annotations

import numpy as np
import pytest

from calib.diagnosis.basis import RCOND, _orth, column_scale, make_basis


def _geometries():
    rng = np.random.default_rng(4)
    full = rng.normal(size=(900, 14)) * rng.uniform(1e-3, 1e2, 14)
    deficient = full.copy()
    deficient[:, 5] = 2.0 * deficient[:, 4]
    zero = full.copy()
    zero[:, 7] = 0.0
    return {"full": full, "deficient": deficient, "zero column": zero}


@pytest.mark.parametrize("name", ["full", "deficient", "zero column"])
@pytest.mark.parametrize("keep", [True, False])
def test_basis_is_numpys_orth_and_pinv(name, keep):
    g = _geometries()[name]
    scale = column_scale(g)
    # numpy's own: the basis _orth makes, np.linalg.pinv
    q_ref = _orth(g / scale)
    gplus_ref = np.linalg.pinv(g / scale, rcond=RCOND) / scale[:, None]
    b = make_basis(g, keep)
    assert (b.kept_pinv is not None) == keep
    np.testing.assert_array_equal(b.q, q_ref)
    assert b.q.strides == q_ref.strides
    assert (b.u is None) == (name == "full")  # U kept only when Q lacks some of its columns
    for _ in range(2):  # kept, or made again each time: the same
        np.testing.assert_array_equal(b.pinv(), gplus_ref)
        assert b.pinv().strides == gplus_ref.strides
    # what a basis is: orthonormal columns spanning G, and G+ G = I on the identifiable part
    np.testing.assert_allclose(b.q.T @ b.q, np.eye(b.q.shape[1]), atol=1e-12)
    np.testing.assert_allclose(g - b.q @ (b.q.T @ g), 0.0, atol=1e-10 * np.abs(g).max())
    if name == "full":
        np.testing.assert_allclose(b.pinv() @ g, np.eye(g.shape[1]), atol=1e-8)
