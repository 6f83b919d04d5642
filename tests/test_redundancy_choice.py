"""The choice of redundant members to fix (calib.fit.redundancy) against the brute-force rule
it computes in closed form: for each null dimension, every candidate's least-squares problem
solved on its own, the smallest null-space move chosen, ties (within TIE) to the later one."""

import numpy as np
import pytest

from calib.fit.redundancy import MEMBER_RTOL, TIE, choose_fixed, null_basis


def _brute_force(v0: np.ndarray, u: np.ndarray, n_null: int, zero: np.ndarray) -> list[int]:
    norms = np.linalg.norm(v0, axis=1)
    member = norms > MEMBER_RTOL * norms.max()
    fixed = [int(j) for j in np.flatnonzero(zero)]
    while len(fixed) < n_null:
        best, best_cost = -1, np.inf
        basis = v0[fixed] if fixed else np.zeros((0, v0.shape[1]))
        for j in range(len(v0)):
            if j in fixed or not member[j]:
                continue
            row = v0[j]
            if len(basis):
                row = row - basis.T @ np.linalg.lstsq(basis.T, row, rcond=None)[0]
            if np.linalg.norm(row) <= MEMBER_RTOL * norms[j]:
                continue
            sel = [*fixed, j]
            cost = float(np.linalg.norm(v0 @ np.linalg.lstsq(v0[sel], u[sel], rcond=None)[0]))
            if cost <= best_cost * (1 + TIE) + 1e-300:
                best, best_cost = j, min(cost, best_cost)
        if best < 0:
            break
        fixed.append(best)
    return sorted(fixed)


def _problem(seed: int, m: int = 60, n: int = 24, rank: int = 15):
    """A Jacobian of ``rank`` with exactly redundant groups (copies and combinations of
    columns, one column with no effect) and a residual."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(m, rank))
    mix = np.zeros((rank, n))
    mix[:, :rank] = np.eye(rank)
    ranges = rng.uniform(0.5, 2.0, n)
    for j in range(rank, n):  # the rest: exact copies (ties) or combinations of a few
        if j % 3 == 0:  # a copy in the same range: exactly tied with its source
            source = int(rng.integers(rank))
            mix[source, j], ranges[j] = 1.0, ranges[source]
        else:
            picks = rng.choice(rank, size=rng.integers(1, 4), replace=False)
            mix[picks, j] = rng.normal(size=len(picks))
    jac = base @ mix
    zero = np.zeros(n, bool)
    zero[n - 1] = True
    jac[:, zero] = 0.0
    return jac, rng.normal(size=m), ranges, zero


@pytest.mark.parametrize("seed", range(12))
def test_closed_form_choice_equals_brute_force(seed):
    jac, residual, ranges, zero = _problem(seed)
    a_u = jac * ranges
    n_null = jac.shape[1] - np.linalg.matrix_rank(a_u)
    got = choose_fixed(jac, residual, ranges, n_null, zero)
    v0, (v1, s1) = null_basis(a_u, n_null)
    u = v1 @ ((a_u @ v1).T @ residual / s1**2)
    assert list(got.fixed) == _brute_force(v0, u, n_null, zero)
    assert len(got.fixed) == n_null
    # fixing them leaves a full-rank problem: the null space is gone
    keep = np.setdiff1d(np.arange(jac.shape[1]), got.fixed)
    assert np.linalg.matrix_rank(a_u[:, keep]) == len(keep)
