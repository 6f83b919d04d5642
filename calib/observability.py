"""Observability indices of an identification Jacobian (all on the column-scaled Jacobian).

With the singular values s_1 >= ... >= s_n of the scaled Jacobian (m rows, n parameters):

* ``product`` (Borm and Meng's O1): (s_1 s_2 ... s_n)^(1/n) / sqrt(m), to maximise;
* ``condition`` (O2, the second paper's Eq. 7): s_1 / s_n, to minimise;
* ``min_singular`` (O3): s_n, to maximise;
* ``noise_amplification`` (Nahvi and Hollerbach's O4): s_n^2 / s_1, to maximise;
* ``d_optimality``: log det(J^T J) = 2 sum log s_i, to maximise.
Every index is undefined for a rank-deficient Jacobian: it raises IdentifiabilityError
unless ``allow_deficient`` is set, in which case the index is returned as its worst value.
"""

from __future__ import annotations

import numpy as np

from calib.exceptions import IdentifiabilityError
from calib.identifiability import RANK_RTOL, scaled_jacobian

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


def all_indices(jac: np.ndarray) -> dict[str, float]:
    return {name: observability(jac, name) for name in INDICES}


def better(name: str, a: float, b: float) -> bool:
    """Is index value ``a`` better than ``b``?"""
    return a > b if MAXIMISE[name] else a < b
