"""Observability indices: analytic identities and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from calib.analysis.observability_indices import (
    INDICES,
    all_indices,
    better,
    index_with_each,
    observability,
)
from calib.exceptions import IdentifiabilityError


def test_orthonormal_columns_are_ideal():
    q, _ = np.linalg.qr(np.random.default_rng(0).normal(size=(40, 6)))
    idx = all_indices(q)
    assert idx["condition"] == pytest.approx(1.0, abs=1e-12)
    assert idx["min_singular"] == pytest.approx(1.0, abs=1e-12)
    assert idx["noise_amplification"] == pytest.approx(1.0, abs=1e-12)
    assert idx["d_optimality"] == pytest.approx(0.0, abs=1e-12)
    assert idx["product"] == pytest.approx(1.0 / np.sqrt(40), abs=1e-12)


def test_known_singular_values():
    u, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(10, 3)))
    v, _ = np.linalg.qr(np.random.default_rng(2).normal(size=(3, 3)))
    # columns of u @ diag(s) @ v^T are not unit norm; build unit columns with known s instead
    s = np.array([1.5, 1.0, 0.5])
    j = u @ np.diag(s) @ v.T
    j /= np.linalg.norm(j, axis=0)
    sv = np.linalg.svd(j, compute_uv=False)
    assert observability(j, "condition") == pytest.approx(sv[0] / sv[-1], rel=1e-12)
    assert observability(j, "product") == pytest.approx(np.prod(sv) ** (1 / 3) / np.sqrt(10))
    assert observability(j, "noise_amplification") == pytest.approx(sv[-1] ** 2 / sv[0])
    assert observability(j, "d_optimality") == pytest.approx(np.log(np.prod(sv**2)))


def test_indices_do_not_depend_on_units():
    j = np.random.default_rng(3).normal(size=(30, 5))
    scaled = j * np.array([1.0, 1e3, 1e-3, 57.3, 1.0])
    for name in INDICES:
        assert observability(j, name) == pytest.approx(observability(scaled, name), rel=1e-10)


def test_rank_deficient_is_an_error_or_the_worst_value():
    j = np.random.default_rng(4).normal(size=(20, 4))
    j[:, 3] = j[:, 0] + j[:, 1]
    with pytest.raises(IdentifiabilityError, match="rank 3 for 4 parameters"):
        observability(j, "condition")
    assert observability(j, "condition", allow_deficient=True) == np.inf
    assert observability(j, "d_optimality", allow_deficient=True) == -np.inf
    with pytest.raises(IdentifiabilityError, match="3 equations"):
        observability(np.ones((3, 4)), "product")
    with pytest.raises(ValueError, match="unknown observability index"):
        observability(j, "volume")


def test_better_follows_the_direction_of_each_index():
    assert better("condition", 2.0, 3.0)
    assert better("product", 3.0, 2.0)


def _stacked_indices(base: np.ndarray, blocks: np.ndarray, name: str) -> np.ndarray:
    return np.array(
        [observability(np.vstack([base, b]), name, allow_deficient=True) for b in blocks]
    )


def test_index_with_each_equals_the_stacked_index():
    rng = np.random.default_rng(5)
    units = np.logspace(-3, 2, 12)  # columns in very different units
    base = rng.normal(size=(20, 12)) * units
    blocks = rng.normal(size=(7, 3, 12)) * units
    for name in INDICES:
        np.testing.assert_allclose(
            index_with_each(base, blocks, name), _stacked_indices(base, blocks, name), rtol=1e-12
        )
    # a base with fewer rows than parameters: the block completes it or the index is worst
    np.testing.assert_allclose(
        index_with_each(base[:10], blocks, "condition"),
        _stacked_indices(base[:10], blocks, "condition"),
        rtol=1e-12,
    )
    assert np.all(index_with_each(base[:5], blocks, "condition") == np.inf)


def test_index_with_each_sees_rank_deficiency_like_the_stack():
    rng = np.random.default_rng(6)
    base = rng.normal(size=(15, 5))
    blocks = rng.normal(size=(4, 3, 5))
    base[:, 4] = base[:, 0] - base[:, 2]
    blocks[1:, :, 4] = blocks[1:, :, 0] - blocks[1:, :, 2]  # only block 0 restores the rank
    values = index_with_each(base, blocks, "d_optimality")
    assert np.isfinite(values[0]) and np.all(values[1:] == -np.inf)
    np.testing.assert_allclose(values, _stacked_indices(base, blocks, "d_optimality"), rtol=1e-12)
    base[:, 3] = 0.0
    blocks[:, :, 3] = 1e-14 * base[:3, 0]  # round-off next to unit columns: zeroed, not scaled
    assert np.all(index_with_each(base, blocks, "condition") == np.inf)
    assert np.all(_stacked_indices(base, blocks, "condition") == np.inf)
