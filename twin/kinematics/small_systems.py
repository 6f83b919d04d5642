"""Many small dense linear systems solved at once, vectorised over the last axis.

LAPACK through ``numpy.linalg`` costs about a microsecond per system on stacks of 6 x 6
matrices, mostly call overhead; the systems of batched kinematics are that small and come by
the thousand. Here a Python loop runs over the few rows and columns and every numpy operation
covers all systems at once. Layout: (rows, columns, L) with the L systems last.

* :func:`eliminate`: Householder reflections (orthogonal: least squares preserved, no pivots
  needed, backward stable);
* :func:`eliminate_static`: Gaussian elimination with the pivots on the diagonal (rows put in
  order beforehand), reporting the systems whose pivots fail a threshold test;
* :func:`solve_square`: square systems by static pivots, Householder for the systems whose
  pivots are refused; :func:`solve_dense`: Householder throughout (least squares when there
  are more rows than unknowns).
"""

from __future__ import annotations

import numpy as np

THRESHOLD = 0.1  # a static pivot must be at least this fraction of the largest entry below it


def eliminate(mat: np.ndarray, k: int) -> None:
    """Householder reflections on the first ``k`` columns of ``mat`` (rows, cols, L), in
    place, independently for each of the L systems: the first k rows become upper triangular
    (with their right-hand columns), the others the reduced rows (an orthonormal basis of the
    complement of those k columns applied to the rest, so least squares is preserved)."""
    rows = mat.shape[0]
    for j in range(min(k, rows)):
        x = mat[j:, j]  # (rows - j, L)
        norm = np.sqrt(np.einsum("rl,rl->l", x, x))
        alpha = np.where(x[0] > 0, -norm, norm)  # reflect away from x0: no cancellation
        v = x.copy()
        v[0] -= alpha
        vtv = 2.0 * norm * (norm + np.abs(x[0]))  # |x - alpha e1|^2
        beta = np.where(vtv > 0, 2.0 / np.where(vtv > 0, vtv, 1.0), 0.0)
        if j + 1 < mat.shape[1]:
            rest = mat[j:, j + 1 :]
            w = np.einsum("rl,rcl->cl", v, rest) * beta
            rest -= v[:, None] * w[None]
        mat[j, j] = alpha
        mat[j + 1 :, j] = 0.0


def eliminate_static(mat: np.ndarray, k: int, threshold: float = THRESHOLD) -> np.ndarray:
    """Gaussian elimination of the first ``k`` columns of ``mat`` (rows, cols, L) in place,
    pivots on the diagonal (the rows already ordered), independently for each of the L
    systems; returns which systems had every pivot at least ``threshold`` times the largest
    entry below it (threshold pivoting: bounded growth). The others must be redone.

    Row by row (one pivot row times one factor at a time) into a scratch row: the working set
    stays in cache, where one broadcast product over every row below the pivot would not."""
    rows = mat.shape[0]
    ok = np.ones(mat.shape[-1], dtype=bool)
    scratch = np.empty(mat.shape[1:])
    factor = np.empty(mat.shape[-1])
    with np.errstate(divide="ignore", invalid="ignore"):
        for j in range(min(k, rows)):
            col = np.abs(mat[j:, j])
            piv = col[0]
            ok &= (piv > 0) & (piv >= threshold * np.max(col, axis=0))
            pivot_row = mat[j, j + 1 :]
            tmp = scratch[j + 1 :]
            for i in range(j + 1, rows):
                np.divide(mat[i, j], mat[j, j], out=factor)
                np.multiply(pivot_row, factor, out=tmp)
                np.subtract(mat[i, j + 1 :], tmp, out=mat[i, j + 1 :])
                mat[i, j] = 0.0
    return ok


def back_substitute(u: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with u x = rhs for upper-triangular u (k, k, ...) and rhs (k, m, ...) (any trailing
    axes: the systems)."""
    k = u.shape[0]
    x = np.empty(rhs.shape)
    for i in range(k - 1, -1, -1):
        if i < k - 1:
            acc = rhs[i] - np.einsum("t...,tm...->m...", u[i, i + 1 :], x[i + 1 :])
        else:
            acc = rhs[i]
        np.divide(acc, u[i, i], out=x[i])
    return x


def solve_dense(mat: np.ndarray, s: int) -> np.ndarray:
    """Solve the systems [A | B] (R, s + m, L) for X (s, m, L): A X = B, in the
    least-squares sense when R > s (Householder, then back substitution)."""
    mat = np.array(mat)
    eliminate(mat, s)
    return back_substitute(mat[:s, :s], mat[:s, s:])


def solve_square(mat: np.ndarray, threshold: float = THRESHOLD) -> np.ndarray:
    """Solve the square systems [A | B] (s, s + m, L) for X (s, m, L), in place on ``mat``:
    Gaussian elimination with the pivots on the diagonal (order the rows beforehand, e.g. by
    partial pivoting on a typical system), and Householder for every system whose pivots
    fail the threshold test (a singular A gives inf or nan, as LAPACK would raise)."""
    s = mat.shape[0]
    saved = mat.copy()
    ok = eliminate_static(mat, s, threshold)
    if not np.all(ok):
        again = saved[..., ~ok]
        eliminate(again, s)
        mat[..., ~ok] = again
    with np.errstate(divide="ignore", invalid="ignore"):
        return back_substitute(mat[:, :s], mat[:, s:])


def pivot_order(a: np.ndarray, k: int) -> np.ndarray:
    """Row order (rows,) of partial pivoting on the first ``k`` columns of one matrix
    (rows, cols): the rows in the order the pivots chose them, the rest after."""
    a = np.array(a, dtype=float)
    order = np.arange(a.shape[0])
    for j in range(min(k, a.shape[0])):
        p = j + int(np.argmax(np.abs(a[j:, j])))
        a[[j, p]], order[[j, p]] = a[[p, j]], order[[p, j]]
        if a[j, j] != 0.0:
            a[j + 1 :] -= np.outer(a[j + 1 :, j] / a[j, j], a[j])
    return order
