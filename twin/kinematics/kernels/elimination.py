"""The closure solve of one pose: motion axes, closure blocks, elimination per closure."""

from __future__ import annotations

import math

import numba as nb

from twin.kinematics.kernels.jit import AXIS_BODY, AXIS_WORLD, JIT


@nb.njit(**JIT)
def householder(a, rows, k, ncol, v):
    """Householder reflections on the first k columns of a[:rows, :ncol], in place (as
    twin.kinematics.small_systems.eliminate); v a (rows,) scratch."""
    for j in range(min(k, rows)):
        norm = 0.0
        for i in range(j, rows):
            norm += a[i, j] * a[i, j]
        norm = math.sqrt(norm)
        x0 = a[j, j]
        alpha = -norm if x0 > 0 else norm
        for i in range(j, rows):
            v[i] = a[i, j]
        v[j] -= alpha
        vtv = 2.0 * norm * (norm + abs(x0))
        beta = 2.0 / vtv if vtv > 0 else 0.0
        for c in range(j + 1, ncol):
            dot = 0.0
            for i in range(j, rows):
                dot += v[i] * a[i, c]
            dot *= beta
            for i in range(j, rows):
                a[i, c] -= v[i] * dot
        a[j, j] = alpha
        for i in range(j + 1, rows):
            a[i, j] = 0.0


@nb.njit(**JIT)
def gauss(a, rows, k, ncol):
    """Gaussian elimination with partial pivoting on the first k columns of a[:rows, :ncol],
    in place: the first k rows upper triangular, the rows below them reduced."""
    for j in range(min(k, rows)):
        p = j
        big = abs(a[j, j])
        for i in range(j + 1, rows):
            if abs(a[i, j]) > big:
                big, p = abs(a[i, j]), i
        if p != j:
            for c in range(j, ncol):
                a[j, c], a[p, c] = a[p, c], a[j, c]
        for i in range(j + 1, rows):
            f = a[i, j] / a[j, j]
            for c in range(j + 1, ncol):
                a[i, c] -= f * a[j, c]
            a[i, j] = 0.0


@nb.njit(**JIT)
def back_substitute(a, n, rhs_col, x):
    """x[:n] with a[:n, :n] x = a[:n, rhs_col], a upper triangular."""
    for i in range(n - 1, -1, -1):
        acc = a[i, rhs_col]
        for t in range(i + 1, n):
            acc -= a[i, t] * x[t]
        x[i] = acc / a[i, i]


@nb.njit(**JIT)
def dof_axes(xmat, xanchor, xaxis, dof_kind, dof_joint, dof_body, dof_col, axes, anchors):
    """World axes and anchors (nf, 3) of the free dofs (as ClosureStructure.dof_axes)."""
    for f in range(dof_kind.size):
        j = dof_joint[f]
        kind = dof_kind[f]
        for i in range(3):
            anchors[f, i] = xanchor[j, i]
            if kind == AXIS_WORLD:
                axes[f, i] = 1.0 if i == dof_col[f] else 0.0
            elif kind == AXIS_BODY:
                axes[f, i] = xmat[dof_body[f], i, dof_col[f]]
            else:
                axes[f, i] = xaxis[j, i]


@nb.njit(**JIT)
def closure_block(c, sp, axes, anchors, dof_rot, moves, cl_rows, cl_k, cl_private, shared, b):
    """Closure c's Jacobian rows (3 or 6) over its private columns, then the shared ones,
    into b[:rows, :k + s] (as ClosureStructure's entries): a rotational dof about the world
    axis w turns the sites it moves by w and moves them by ``w x (p - anchor)``, a
    translational one moves them by w; the column is the first site's motion less the
    second's (``w x (p_a - p_b)`` when it moves both)."""
    nc = cl_rows.size
    rows, k, s = cl_rows[c], cl_k[c], shared.size
    for j in range(k + s):
        f = cl_private[c, j] if j < k else shared[j - k]
        ma = moves[c, f] != 0
        mb = moves[nc + c, f] != 0
        sign = (1.0 if ma else 0.0) - (1.0 if mb else 0.0)
        w0, w1, w2 = axes[f, 0], axes[f, 1], axes[f, 2]
        if not dof_rot[f]:
            b[0, j], b[1, j], b[2, j] = sign * w0, sign * w1, sign * w2
            for i in range(3, rows):
                b[i, j] = 0.0
            continue
        if ma and mb:
            l0 = sp[c, 0] - sp[nc + c, 0]
            l1 = sp[c, 1] - sp[nc + c, 1]
            l2 = sp[c, 2] - sp[nc + c, 2]
            m = 1.0
        else:
            e = c if ma else nc + c
            l0 = sp[e, 0] - anchors[f, 0]
            l1 = sp[e, 1] - anchors[f, 1]
            l2 = sp[e, 2] - anchors[f, 2]
            m = sign
        b[0, j] = m * (w1 * l2 - w2 * l1)
        b[1, j] = m * (w2 * l0 - w0 * l2)
        b[2, j] = m * (w0 * l1 - w1 * l0)
        if rows == 6:
            b[3, j], b[4, j], b[5, j] = sign * w0, sign * w1, sign * w2


@nb.njit(**JIT)
def closure_step(
    r, sp, axes, anchors, dof_rot, moves, cl_rows, cl_off, cl_k, cl_private, shared, square,
    blocks, red, v, xs, step,
):  # fmt: skip
    """The Newton step (nf,) solving J step = -r by elimination per closure: Gaussian
    elimination with partial pivoting when the system is square, Householder (least squares
    preserved) when it is over-determined."""
    nc = cl_rows.size
    s = shared.size
    n_red = 0
    for c in range(nc):
        rows, k = cl_rows[c], cl_k[c]
        b = blocks[c]
        closure_block(c, sp, axes, anchors, dof_rot, moves, cl_rows, cl_k, cl_private, shared, b)
        for i in range(rows):
            b[i, k + s] = -r[cl_off[c] + i]
        if square:
            gauss(b, rows, k, k + s + 1)
        else:
            householder(b, rows, k, k + s + 1, v)
        for i in range(k, rows):
            for j in range(s + 1):
                red[n_red, j] = b[i, k + j]
            n_red += 1
    if s:
        if n_red == s:
            gauss(red, s, s, s + 1)
        else:
            householder(red, n_red, s, s + 1, v)
        back_substitute(red, s, s, xs)
        for j in range(s):
            step[shared[j]] = xs[j]
    for c in range(nc):
        k = cl_k[c]
        if not k:
            continue
        b = blocks[c]
        for i in range(k):  # the shared columns' part moved to the right-hand side
            acc = b[i, k + s]
            for j in range(s):
                acc -= b[i, k + j] * xs[j]
            b[i, k + s] = acc
        back_substitute(b, k, k + s, v)
        for j in range(k):
            step[cl_private[c, j]] = v[j]
