"""Observability indices: analytic identities and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from calib.exceptions import IdentifiabilityError
from calib.observability import INDICES, all_indices, better, observability


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
