"""The projection basis of a training set's geometric columns G: Q (orthonormal, for the
projections) and G+ (the pseudo-inverse, for the geometric correction beta = G+ r), both from
one SVD of the unit-scaled columns.

A diagnosis reads the bases of 55 training sets (every outer and inner fold of its
cross-validation), each Q and G+ as large as the set's rows times the parameters. Q is read
everywhere and kept; G+ only by a fit's beta, so the pseudo-inverses are kept while they take
at most ``PINV_BUDGET`` bytes together, and beyond that each is made again from the SVD's
factors when a fit asks for it (the same arithmetic, so the same numbers): a diagnosis of
100,000 readings holds about half the memory for a few per cent more time, one of 10,000
keeps them all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RCOND = 1e-10
PINV_BUDGET = 1 << 30  # bytes of pseudo-inverses kept per problem


def _kept(s: np.ndarray) -> np.ndarray:
    """Which singular values (largest first) span the columns: above RCOND of the largest."""
    return s > RCOND * max(s[0], 1e-300)


def _orth(a: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the column space of ``a`` (rank-revealing SVD)."""
    if a.shape[1] == 0:
        return np.zeros((a.shape[0], 0))
    u, s, _ = np.linalg.svd(a, full_matrices=False)
    return u[:, _kept(s)]


def _inverse(s: np.ndarray) -> np.ndarray:
    """1 / s where s is above RCOND of the largest, 0 elsewhere (numpy's pinv)."""
    large = s > RCOND * np.max(s)
    inv = np.divide(1, s, where=large, out=s.copy())
    inv[~large] = 0
    return inv


@dataclass(frozen=True)
class Basis:
    """Q and the factors of G+ of one training set (G+ itself when it is kept)."""

    q: np.ndarray  # (rows, rank) orthonormal: U's kept columns, column-major
    u: np.ndarray | None  # (rows, p) the SVD's U when Q lacks some of its columns
    vt: np.ndarray | None  # (p, p)
    inv: np.ndarray | None  # (p,) 1 / singular value, 0 where dropped
    scale: np.ndarray  # (p,) the columns' norms (1 for a zero column)
    kept_pinv: np.ndarray | None  # (p, rows) G+ when kept

    def pinv(self) -> np.ndarray:
        """G+ (p, rows) of the unscaled columns."""
        if self.kept_pinv is not None:
            return self.kept_pinv
        assert self.vt is not None and self.inv is not None
        return pinv_of(self.q if self.u is None else self.u, self.vt, self.inv, self.scale)


def pinv_of(u: np.ndarray, vt: np.ndarray, inv: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """G+ from the SVD's U (or the same values in another memory order), V^T and inverted
    singular values of the scaled columns, and the scale: the arithmetic of numpy's pinv, its
    product's operand column-major as numpy's U^T gives it (a BLAS product's order of sums,
    so its last bits, follow the operands' layout)."""
    ut = np.multiply(inv[:, None], u.T, out=np.empty(u.T.shape, order="F"))
    return np.matmul(vt.T, ut) / scale[:, None]


def column_scale(g: np.ndarray) -> np.ndarray:
    scale = np.linalg.norm(g, axis=0)
    scale[scale == 0] = 1.0
    return scale


def make_basis(g: np.ndarray, keep_pinv: bool) -> Basis:
    """The basis of the geometric columns ``g`` (rows, p); G+ made and kept when asked."""
    scale = column_scale(g)
    a = g / scale
    if a.size == 0:
        gplus = np.linalg.pinv(a, rcond=RCOND)
        return Basis(_orth(a), None, None, None, scale, gplus / scale[:, None])
    u, s, vt = np.linalg.svd(a, full_matrices=False)
    keep = _kept(s)
    q = u[:, keep]  # a column-major copy (numpy's U is row-major), as _orth's
    inv = _inverse(s)
    full = None if keep.all() else u  # else Q's values are U's
    kept = pinv_of(u, vt, inv, scale) if keep_pinv else None
    return Basis(q, full, vt, inv, scale, kept)
