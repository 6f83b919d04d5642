"""The compiled Newton of batched forward kinematics (numba), one pose after another.

Per pose and step (twin.kinematics_compiled_kernels has the frames): the closure residual,
the closure Jacobian block of each closure over its private columns and the shared ones
(entries as twin.kinematics_reduced: a rotational dof moves a site by ``w x (p - anchor)``
and turns it by ``w``, a translational one moves it by ``w``; a dof that moves both sites of a
closure adds the difference), Householder on each block's private columns, the reduced system
over the shared columns (partial pivoting when square, Householder least squares when
over-determined), back substitution, the damped step and ``mj_integratePos``.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from twin.kinematics_compiled_kernels import (
    AXIS_BODY,
    AXIS_WORLD,
    FREE,
    JIT,
    rotvec_of_product,
    site_frame,
    tree,
)


@nb.njit(**JIT)
def householder(a, rows, k, ncol, v):
    """Householder reflections on the first k columns of a[:rows, :ncol], in place (as
    twin.small_systems.eliminate); v a (rows,) scratch."""
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
def closure_step(
    r, sp, axes, anchors, dof_rot, moves, cl_rows, cl_off, cl_k, cl_private, shared, square,
    blocks, red, v, xs, step,
):  # fmt: skip
    """The Newton step (nf,) solving J step = -r by elimination per closure: Gaussian
    elimination with partial pivoting when the system is square, Householder (least squares
    preserved) when it is over-determined.

    Closure c's column of free dof f (as ClosureStructure's entries): a rotational dof about
    the world axis w turns the sites it moves by w and moves them by ``w x (p - anchor)``, a
    translational one moves them by w; the column is the first site's motion less the
    second's (``w x (p_a - p_b)`` when it moves both)."""
    nc = cl_rows.size
    s = shared.size
    n_red = 0
    for c in range(nc):
        rows, k = cl_rows[c], cl_k[c]
        b = blocks[c]
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
                l0, l1, l2 = (
                    sp[e, 0] - anchors[f, 0],
                    sp[e, 1] - anchors[f, 1],
                    sp[e, 2] - anchors[f, 2],
                )
                m = sign
            b[0, j] = m * (w1 * l2 - w2 * l1)
            b[1, j] = m * (w2 * l0 - w0 * l2)
            b[2, j] = m * (w0 * l1 - w1 * l0)
            if rows == 6:
                b[3, j], b[4, j], b[5, j] = sign * w0, sign * w1, sign * w2
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


@nb.njit(**JIT)
def turn_quat(q, a, r0, r1, r2):
    """q[a:a+4] <- q[a:a+4] * quat(rotation vector), normalised (mj_integratePos)."""
    angle = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if angle < 1e-10:
        s = 0.5 - angle * angle / 48.0
    else:
        s = math.sin(angle / 2) / angle
    bw, bx, by, bz = math.cos(angle / 2), r0 * s, r1 * s, r2 * s
    aw, ax, ay, az = q[a], q[a + 1], q[a + 2], q[a + 3]
    w = aw * bw - (ax * bx + ay * by + az * bz)
    x = aw * bx + bw * ax + (ay * bz - az * by)
    y = aw * by + bw * ay + (az * bx - ax * bz)
    z = aw * bz + bw * az + (ax * by - ay * bx)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    q[a], q[a + 1], q[a + 2], q[a + 3] = w / norm, x / norm, y / norm, z / norm


@nb.njit(**JIT)
def integrate(q, step, simple_qpos, simple_rows, multi_type, multi_qpos, multi_rows):
    for i in range(simple_qpos.size):
        q[simple_qpos[i]] += step[simple_rows[i]]
    for m in range(multi_type.size):
        a = multi_qpos[m]
        rows = multi_rows[m]
        if multi_type[m] == FREE:
            for i in range(3):
                q[a + i] += step[rows[i]]
            turn_quat(q, a + 3, step[rows[3]], step[rows[4]], step[rows[5]])
        else:
            turn_quat(q, a, step[rows[0]], step[rows[1]], step[rows[2]])


@nb.njit(**JIT)
def newton_batch(
    qs, structure, numbers, closure, dofs, motion, out_sites, settings,
    out_pos, out_rot, residual, iterations,
):  # fmt: skip
    """Forward kinematics of the configurations qs (N, nq), in place (actuators set, the rest
    a start): sites ``out_sites`` positions into out_pos (N, S, 3), the first one's rotation
    into out_rot (N, 3, 3), the largest closure residual component and the Newton iteration
    of each pose. ``settings`` = (tolerance, accept, max_iter, max_step)."""
    parent, jnt_adr, jnt_num, jnt_type, jnt_qposadr, site_body = structure
    body_pos, body_rot, jnt_pos, jnt_axis, jnt_unit, qpos0, site_pos, site_rot, turned = numbers
    cl_sites, cl_rows, cl_off, cl_k, cl_private, shared, moves, square = closure
    dof_kind, dof_joint, dof_body, dof_col, dof_rot = dofs
    simple_qpos, simple_rows, multi_type, multi_qpos, multi_rows = motion
    tolerance, accept, max_iter, max_step = settings
    nbody, njnt = parent.size, jnt_type.size
    nc, nf, s = cl_rows.size, dof_kind.size, shared.size
    has_weld = np.any(cl_rows == 6)
    kmax = cl_private.shape[1]
    xpos, xmat = np.empty((nbody, 3)), np.empty((nbody, 3, 3))
    xanchor, xaxis = np.empty((njnt, 3)), np.empty((njnt, 3))
    local = np.empty((3, 3))
    sp, srot = np.empty((2 * nc, 3)), np.empty((2 * nc, 3, 3))
    r = np.empty(max(1, cl_rows.sum()))
    blocks = np.empty((max(1, nc), 6, kmax + s + 1))
    red = np.empty((max(1, cl_rows.sum()), s + 1))
    v = np.empty(max(6, cl_rows.sum(), kmax + s + 1))
    xs, step = np.empty(max(1, s)), np.empty(max(1, nf))
    axes, anchors = np.empty((max(1, nf), 3)), np.empty((max(1, nf), 3))
    pos, rot = np.empty(3), np.empty((3, 3))
    for n in range(qs.shape[0]):
        q = qs[n]
        best, stall = np.inf, 0
        for it in range(max_iter + 1):
            tree(
                q, parent, jnt_adr, jnt_num, jnt_type, jnt_qposadr,
                body_pos, body_rot, jnt_pos, jnt_axis, jnt_unit, qpos0,
                xpos, xmat, xanchor, xaxis, local,
            )  # fmt: skip
            for e in range(2 * nc):  # the closure sites' frames (site_frame, inline)
                st = cl_sites[e]
                bd = site_body[st]
                for i in range(3):
                    sp[e, i] = xpos[bd, i] + (
                        xmat[bd, i, 0] * site_pos[st, 0]
                        + xmat[bd, i, 1] * site_pos[st, 1]
                        + xmat[bd, i, 2] * site_pos[st, 2]
                    )
                if has_weld:
                    site_frame(st, site_body, site_pos, site_rot, turned, xpos, xmat, pos, srot[e])
            err, bad = 0.0, False
            for c in range(nc):
                o = cl_off[c]
                for i in range(3):
                    r[o + i] = sp[c, i] - sp[nc + c, i]
                if cl_rows[c] == 6:
                    rotvec_of_product(srot[c], srot[nc + c], r[o + 3 : o + 6], local)
                for i in range(cl_rows[c]):
                    a = abs(r[o + i])
                    if a != a:
                        bad = True
                    elif a > err:
                        err = a
            if bad:
                err = np.nan
            residual[n] = err
            stall = stall + 1 if err >= 0.5 * best else 0
            best = min(best, err)
            done = err < tolerance or (stall >= 3 and best < accept)
            if done or not math.isfinite(err) or it == max_iter:
                for e in range(out_sites.size):
                    site_frame(out_sites[e], site_body, site_pos, site_rot, turned, xpos, xmat,
                               out_pos[n, e], rot)  # fmt: skip
                    if e == 0:
                        out_rot[n] = rot
                iterations[n] = it
                break
            dof_axes(xmat, xanchor, xaxis, dof_kind, dof_joint, dof_body, dof_col, axes, anchors)
            closure_step(
                r, sp, axes, anchors, dof_rot, moves, cl_rows, cl_off, cl_k, cl_private,
                shared, square, blocks, red, v, xs, step,
            )  # fmt: skip
            norm = 0.0
            for f in range(nf):
                norm += step[f] * step[f]
            norm = math.sqrt(norm)
            if norm > max_step:
                for f in range(nf):
                    step[f] *= max_step / norm
            integrate(q, step, simple_qpos, simple_rows, multi_type, multi_qpos, multi_rows)
