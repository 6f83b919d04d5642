"""Observability indices of an identification Jacobian (all on the column-scaled Jacobian).

With the singular values s_1 >= ... >= s_n of the scaled Jacobian (m rows, n parameters):

* ``product`` (Borm and Meng's O1): (s_1 s_2 ... s_n)^(1/n) / sqrt(m), to maximise;
* ``condition`` (O2, the second paper's Eq. 7): s_1 / s_n, to minimise;
* ``min_singular`` (O3): s_n, to maximise;
* ``noise_amplification`` (Nahvi and Hollerbach's O4): s_n^2 / s_1, to maximise;
* ``d_optimality``: log det(J^T J) = 2 sum log s_i, to maximise.
Every index is undefined for a rank-deficient Jacobian: it raises IdentifiabilityError
unless ``allow_deficient`` is set, in which case the index is returned as its worst value.

``index_with_each`` gives the index of one stack of rows with each of many candidate blocks
appended (pose selection's inner loop) without stacking them: see its docstring.
"""

from __future__ import annotations

import numpy as np

from calib.analysis.identifiability import RANK_RTOL, ZERO_RTOL, column_scale, scaled_jacobian
from calib.exceptions import IdentifiabilityError
from twin.kinematics.structure import one_blas_thread

INDICES = ("product", "condition", "min_singular", "noise_amplification", "d_optimality")
MAXIMISE = {
    "product": True,
    "condition": False,
    "min_singular": True,
    "noise_amplification": True,
    "d_optimality": True,
}


def singular_values(jac: np.ndarray) -> np.ndarray:
    scaled, _, _ = scaled_jacobian(jac)
    return np.linalg.svd(scaled, compute_uv=False)


def index_from_singular_values(s: np.ndarray, n_rows: int, name: str) -> float:
    if name == "product":
        return float(np.exp(np.mean(np.log(s))) / np.sqrt(n_rows))
    if name == "condition":
        return float(s[0] / s[-1])
    if name == "min_singular":
        return float(s[-1])
    if name == "noise_amplification":
        return float(s[-1] ** 2 / s[0])
    if name == "d_optimality":
        return float(2.0 * np.sum(np.log(s)))
    raise ValueError(f"unknown observability index '{name}'; known: {INDICES}")


def observability(jac: np.ndarray, name: str, allow_deficient: bool = False) -> float:
    """One index of ``jac`` (m, n); see the module docstring."""
    if name not in INDICES:
        raise ValueError(f"unknown observability index '{name}'; known: {INDICES}")
    jac = np.asarray(jac, dtype=float)
    m, n = jac.shape
    s = singular_values(jac)
    deficient = m < n or s.size < n or s[-1] <= RANK_RTOL * s[0]
    if deficient:
        if allow_deficient:
            return -np.inf if MAXIMISE[name] else np.inf
        rank = int(np.sum(s > RANK_RTOL * s[0])) if s.size else 0
        raise IdentifiabilityError(
            f"the {name} index is undefined: the Jacobian has rank {rank} for {n} parameters "
            f"({m} equations)"
        )
    return index_from_singular_values(s, m, name)


def _indices_of_rows(s: np.ndarray, n_rows: int, name: str) -> np.ndarray:
    """``index_from_singular_values`` for each row of ``s`` (C, n), descending rows."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if name == "product":
            return np.exp(np.mean(np.log(s), axis=1)) / np.sqrt(n_rows)
        if name == "condition":
            return s[:, 0] / s[:, -1]
        if name == "min_singular":
            return s[:, -1].copy()
        if name == "noise_amplification":
            return s[:, -1] ** 2 / s[:, 0]
        if name == "d_optimality":
            return 2.0 * np.sum(np.log(s), axis=1)
    raise ValueError(f"unknown observability index '{name}'; known: {INDICES}")


def index_with_each(base: np.ndarray, blocks: np.ndarray, name: str) -> np.ndarray:
    """The index of ``vstack([base, blocks[c]])`` for every candidate ``c``, as
    ``observability(..., allow_deficient=True)`` would give it (to round-off).

    ``base`` (m, n), ``blocks`` (C, k, n). With ``base / d0 = Q R`` (d0 its column norms),
    ``[base; b] = diag(Q, I) [R d0; b]``: the stack's singular values are those of the small
    ``[R d0; b]``, column-scaled by the stack's own norms (their squares add over rows) and
    with its round-off columns zeroed as in ``scaled_jacobian``. One QR of the base, one
    batched SVD of C matrices of at most n + k rows (``d_optimality`` of a base far from rank
    deficiency: the determinant lemma instead), BLAS on one thread.
    """
    if name not in INDICES:
        raise ValueError(f"unknown observability index '{name}'; known: {INDICES}")
    base = np.asarray(base, dtype=float)
    blocks = np.asarray(blocks, dtype=float)
    m, n = base.shape
    n_cand, k = blocks.shape[0], blocks.shape[1]
    worst = -np.inf if MAXIMISE[name] else np.inf
    if n_cand == 0:
        return np.zeros(0)
    with one_blas_thread():
        d0 = column_scale(base)
        r = np.linalg.qr(base / d0, mode="r") * d0  # (min(m, n), n): same Gram as base
        norms = np.sqrt(np.sum(base**2, axis=0)[None] + np.sum(blocks**2, axis=1))  # (C, n)
        top = norms.max(axis=1, keepdims=True)
        zero = (norms <= ZERO_RTOL * top) | (top <= 0)
        inv = np.where(zero, 0.0, 1.0 / np.where(norms > 0, norms, 1.0))[:, None, :]
        if name == "d_optimality" and m >= n and not np.any(zero):
            logdet = _logdet_with_each(r, blocks, inv[:, 0])
            if logdet is not None:
                return logdet
        stacked = np.concatenate([np.broadcast_to(r, (n_cand, *r.shape)), blocks], axis=1)
        s = np.linalg.svd(stacked * inv, compute_uv=False)  # (C, min(rows, n)), descending
    if m + k < n or s.shape[1] < n:
        return np.full(n_cand, worst)
    values = _indices_of_rows(s, m + k, name)
    deficient = s[:, -1] <= RANK_RTOL * s[:, 0]
    values[deficient] = worst
    return values


def _logdet_with_each(r: np.ndarray, blocks: np.ndarray, inv: np.ndarray) -> np.ndarray | None:
    """``log det`` of each scaled ``[r; b_c] diag(inv_c)`` by the determinant lemma:
    ``2 sum log |diag(r) inv_c| + log det(I + W W^T)``, ``W = b_c r^-1`` (triangular solves,
    a k x k Cholesky). Only when no candidate can be rank deficient: the scaled stack's
    smallest singular value is at least ``s_min(r / d0) min(d0 inv_c)`` and its largest at most
    ``sqrt(n)`` (unit columns); None otherwise (the caller takes the SVD)."""
    n = r.shape[1]
    d0 = column_scale(r)
    s0 = np.linalg.svd(r / d0, compute_uv=False)
    floor = s0[-1] * np.min(d0[None] * inv, axis=1)
    if s0.size < n or np.any(floor <= 1e3 * RANK_RTOL * np.sqrt(n)):
        return None
    c, k = blocks.shape[:2]
    w = np.linalg.solve(r.T, blocks.reshape(c * k, n).T).T.reshape(c, k, n)  # b_c r^-1
    inner = np.eye(k) + w @ w.transpose(0, 2, 1)
    chol = np.linalg.cholesky(inner)
    diag = np.diagonal(chol, axis1=1, axis2=2)
    return 2.0 * np.sum(np.log(np.abs(np.diag(r))[None] * inv), axis=1) + 2.0 * np.sum(
        np.log(diag), axis=1
    )


def all_indices(jac: np.ndarray) -> dict[str, float]:
    return {name: observability(jac, name) for name in INDICES}


def better(name: str, a: float, b: float) -> bool:
    """Is index value ``a`` better than ``b``?"""
    return a > b if MAXIMISE[name] else a < b
