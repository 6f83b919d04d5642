"""rotvec_from_matrix's path for a few matrices (Python floats) against the array path: the
same numbers bit for bit, near 0, near pi, on exact axes and off orthonormality."""

import numpy as np
import pytest

from twin.rotations import _rotvec_from_matrix_array, matrix_from_rotvec, rotvec_from_matrix


def _matrices(rng: np.random.Generator, n: int) -> np.ndarray:
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    kind = rng.integers(0, 5, size=n)
    angle = np.select(
        [kind == 0, kind == 1, kind == 2, kind == 3],
        [
            rng.uniform(0, np.pi, n),
            10.0 ** rng.uniform(-17, -6, n),  # near zero
            np.pi - 10.0 ** rng.uniform(-16, -4, n),  # near pi
            np.zeros(n),
        ],
        np.full(n, np.pi),
    )
    r = matrix_from_rotvec(axis * angle[:, None])
    off = rng.random(n) < 0.2  # a Newton iterate is not exactly orthonormal
    r[off] += rng.normal(scale=1e-9, size=(int(off.sum()), 3, 3))
    return r


def test_one_matrix_matches_the_array_path_bit_for_bit():
    rng = np.random.default_rng(0)
    r = _matrices(rng, 20000)
    r[:5] = [
        np.eye(3),
        np.diag([1.0, -1, -1]),
        np.diag([-1.0, 1, -1]),
        np.diag([-1.0, -1, 1]),
        -np.eye(3),
    ]
    expected = _rotvec_from_matrix_array(r)
    got = np.array([rotvec_from_matrix(m) for m in r])
    np.testing.assert_array_equal(got, expected)
    one_by_one = np.array([_rotvec_from_matrix_array(m) for m in r[:3000]])
    np.testing.assert_array_equal(got[:3000], one_by_one)


@pytest.mark.parametrize("batch", [1, 2, 3, 6, 8, 9])
def test_small_batches_match_the_array_path_bit_for_bit(batch):
    rng = np.random.default_rng(batch)
    r = _matrices(rng, 600 * batch).reshape(-1, batch, 3, 3)
    for stack in r:
        np.testing.assert_array_equal(rotvec_from_matrix(stack), _rotvec_from_matrix_array(stack))
        np.testing.assert_array_equal(
            rotvec_from_matrix(stack), _rotvec_from_matrix_array(stack.copy())
        )


def test_nan_is_left_to_the_array_path():
    r = np.full((3, 3), np.nan)
    assert np.all(np.isnan(rotvec_from_matrix(r)))
    got = rotvec_from_matrix(np.stack([np.eye(3), r]))
    assert got.shape == (2, 3) and np.all(got[0] == 0) and np.all(np.isnan(got[1]))
