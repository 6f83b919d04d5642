"""The adjoint closure solve ``J^T z = b`` for many configurations, by the same elimination.

The identification Jacobian needs ``J_t J^-1 c_pi`` (target motion of the dofs, the closure
Jacobian's inverse, the closures' parameter derivatives): one right-hand side per parameter
forwards, but only one per target coordinate through the adjoint, ``(J^-T J_t^T)^T c_pi``.
The elimination of twin.kinematics.reduced run with an identity right-hand side gives each
closure's row transform ``T`` (``T A = [U; 0]`` for its private columns ``A``), and with it

    z_c = T_c^T [U_c^-T b_c ; w_c],   sum_c B_red,c^T w_c = b_s - sum_c B_top,c^T U_c^-T b_c

for the private right-hand sides ``b_c`` and the shared ones ``b_s``: triangular solves, one
small reduced system per configuration and products, no 36 x 36 factorisation. The reduced
systems (transposed) are solved like the forward ones, vectorised over configurations
(twin.kinematics.small_systems.solve_square: static pivots chosen for the transpose at the home
configuration, Householder where one is refused), not by a LAPACK call per configuration.
Square systems only (the identification of an exactly constrained machine); the caller
falls back otherwise (least squares by the forward elimination). Layout as in
twin.kinematics.reduced (configurations last).
"""

from __future__ import annotations

import numpy as np

from twin.kinematics.reduced import ClosureStructure
from twin.kinematics.small_systems import solve_square
from twin.kinematics.tree import TreeFrames


def adjoint_solve(
    cs: ClosureStructure, frames: TreeFrames, site_pos: np.ndarray, b: np.ndarray
) -> np.ndarray:
    """z (n_closure, m, N) with ``J^T z = b`` for b (n_free, m, N); J the closure Jacobian at
    ``frames`` (``site_pos`` the closure sites' positions, as ClosureStructure.matrices)."""
    if not cs.square:
        raise ValueError("the adjoint solve needs an exactly determined closure system")
    n, m_rhs = b.shape[-1], b.shape[1]
    rmax = max(g.rows for g in cs.groups)
    ident = np.zeros((cs.n_closure, rmax, n))
    for c, off in enumerate(cs.row_offset):
        size = (cs.row_offset[c + 1] if c + 1 < len(cs.row_offset) else cs.n_closure) - off
        ident[off + np.arange(size), np.arange(size)] = 1.0
    mats = cs.matrices(frames, site_pos, ident)
    cs.eliminate_groups(mats, rebuild=lambda: cs.matrices(frames, site_pos, ident))
    s = len(cs.shared)
    rhs_s = b[cs.shared].copy() if s else None
    tops, reduced = [], []
    for g, mat in zip(cs.groups, mats, strict=True):
        k = g.k
        bp = np.moveaxis(b[g.private.T], 2, 1) if k else np.zeros((0, m_rhs, *mat.shape[2:]))
        w_top = _forward_substitute_transposed(mat[:k, :k], bp)  # (k, m, G, N)
        if s:
            rhs_s -= np.einsum("ksgn,kmgn->smn", mat[:k, k : k + s], w_top)
            reduced.append(np.moveaxis(mat[k:, k : k + s], 2, 1).reshape(-1, s, n))
        tops.append(w_top)
    w_red_all = None
    if s:
        red = np.concatenate(reduced)  # (s, s, N): rows (group, slot, row), columns shared
        # red^T w = rhs_s as the system [red^T | rhs_s], its rows in the static pivot order
        # chosen for the transpose (ClosureStructure.order_rows)
        aug = np.concatenate([red.transpose(1, 0, 2), rhs_s], axis=1)[cs.reduced_order_t]
        w_red_all = solve_square(aug)  # (s, m, N)
    z = np.zeros((cs.n_closure, m_rhs, n))
    start = 0
    for g, mat, w_top in zip(cs.groups, mats, tops, strict=True):
        k, r, ng = g.k, g.rows, len(g.closures)
        if s and r > k:
            w_red = w_red_all[start : start + ng * (r - k)].reshape(ng, r - k, m_rhs, n)
            start += ng * (r - k)
            w = np.concatenate([w_top, np.moveaxis(w_red, 0, 2)], axis=0)  # (r, m, G, N)
        else:
            w = w_top
        t = mat[:, k + s : k + s + r]  # (r, r, G, N): transformed rows x original rows
        zc = np.einsum("qrgn,qmgn->rmgn", t[: w.shape[0]], w)
        rows = cs.row_offset[g.closures][None, :] + np.arange(r)[:, None]  # (r, G)
        z[rows] = np.moveaxis(zc, 2, 1)
    return z


def _forward_substitute_transposed(u: np.ndarray, b: np.ndarray) -> np.ndarray:
    """w with u^T w = b, u upper triangular (k, k, ...) and b (k, m, ...)."""
    k = u.shape[0]
    w = np.empty_like(b)
    for i in range(k):
        acc = b[i] - np.einsum("t...,tm...->m...", u[:i, i], w[:i]) if i else b[i]
        w[i] = acc / u[i, i]
    return w
