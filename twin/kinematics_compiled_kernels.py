"""Compiled kernels (numba) of batched forward kinematics: one pose at a time in machine code.

The numpy path (twin.kinematics_batch with twin.kinematics_tree and twin.kinematics_reduced)
spends its time passing over arrays: each Newton step makes some thirty passes over every
pose's frames, at about a nanosecond per element. Here each pose runs the whole Newton in
registers and a few hundred bytes of scratch, from the same model arrays: MuJoCo's
``mj_kinematics`` (bodies parents first, hinge, slide, ball and free joints), the closure
residual (position rows, and the rotation vector of ``R_a R_b^T`` for a weld), the closure
Jacobian over the free dofs (a rotational dof moves a site by ``w x (p - anchor)`` and turns
it by ``w``, a translational one moves it by ``w``; a closure's column is its first site's
motion less its second's), the solve by elimination per closure (each closure's private
columns eliminated, partial pivoting when the system is square, Householder when it is
over-determined, then the reduced system over the shared columns), back substitution, the
damped step and ``mj_integratePos``. Steps, damping of long steps, tolerance and stall rule
are those of twin.kinematics. The identification Jacobian
(:func:`jacobian_batch`) reuses the tree, the closure blocks and their elimination for the
adjoint solve.

Everything is read from arrays the caller builds from the MJCF (twin.kinematics_compiled),
so every machine goes through this one code path. ``nogil``: the caller's threads run poses
side by side. ``cache``: compiled once per environment (numba writes the machine code next
to this file, or to NUMBA_CACHE_DIR). The kernels live in this one file on purpose: numba's
cache notices a change of a function's own file, not of the files its callees are in.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

FREE, BALL, SLIDE, HINGE = 0, 1, 2, 3  # mjtJoint
AXIS_JOINT, AXIS_WORLD, AXIS_BODY = 0, 1, 2  # as twin.kinematics_reduced

JIT = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}
JIT_INLINE = {**JIT, "inline": "always"}  # small helpers: a call passing arrays costs more


@nb.njit(**JIT)
def quat_to_mat(q0, q1, q2, q3, out):
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    w, x, y, z = q0 / norm, q1 / norm, q2 / norm, q3 / norm
    out[0, 0] = 1 - 2 * (y * y + z * z)
    out[0, 1] = 2 * (x * y - w * z)
    out[0, 2] = 2 * (x * z + w * y)
    out[1, 0] = 2 * (x * y + w * z)
    out[1, 1] = 1 - 2 * (x * x + z * z)
    out[1, 2] = 2 * (y * z - w * x)
    out[2, 0] = 2 * (x * z - w * y)
    out[2, 1] = 2 * (y * z + w * x)
    out[2, 2] = 1 - 2 * (x * x + y * y)


@nb.njit(**JIT)
def tree(
    q, parent, jnt_adr, jnt_num, jnt_type, jnt_qposadr,
    body_pos, body_rot, body_turned, jnt_pos, jnt_offset, jnt_axis, jnt_unit, jnt_class,
    jnt_sign, qpos0, xpos, xmat, xanchor, xaxis, local,
):  # fmt: skip
    """``mj_kinematics`` of one configuration q into xpos (nbody, 3), xmat (nbody, 3, 3),
    xanchor and xaxis (njnt, 3); ``local`` a (3, 3) scratch. As twin.kinematics_tree, a body
    without a rotation keeps its parent's, a joint at its body's origin needs no offset, and
    a hinge about a coordinate axis (``jnt_class`` 0-2, ``jnt_sign`` +-1) turns two columns."""
    xpos[0, :] = 0.0
    xmat[0, :, :] = 0.0
    for i in range(3):
        xmat[0, i, i] = 1.0
    for b in range(1, parent.size):
        p = parent[b]
        for i in range(3):
            xpos[b, i] = xpos[p, i] + (
                xmat[p, i, 0] * body_pos[b, 0]
                + xmat[p, i, 1] * body_pos[b, 1]
                + xmat[p, i, 2] * body_pos[b, 2]
            )
            if body_turned[b]:
                for j in range(3):
                    xmat[b, i, j] = (
                        xmat[p, i, 0] * body_rot[b, 0, j]
                        + xmat[p, i, 1] * body_rot[b, 1, j]
                        + xmat[p, i, 2] * body_rot[b, 2, j]
                    )
            else:
                for j in range(3):
                    xmat[b, i, j] = xmat[p, i, j]
        for jn in range(jnt_adr[b], jnt_adr[b] + jnt_num[b]):
            kind = jnt_type[jn]
            a = jnt_qposadr[jn]
            if kind == FREE:
                for i in range(3):
                    xpos[b, i] = q[a + i]
                    xanchor[jn, i] = q[a + i]
                    xaxis[jn, i] = jnt_axis[jn, i]
                quat_to_mat(q[a + 3], q[a + 4], q[a + 5], q[a + 6], xmat[b])
                continue
            cls = jnt_class[jn]
            for i in range(3):
                if jnt_offset[jn]:
                    xanchor[jn, i] = xpos[b, i] + (
                        xmat[b, i, 0] * jnt_pos[jn, 0]
                        + xmat[b, i, 1] * jnt_pos[jn, 1]
                        + xmat[b, i, 2] * jnt_pos[jn, 2]
                    )
                else:
                    xanchor[jn, i] = xpos[b, i]
                if cls < 3:
                    xaxis[jn, i] = jnt_sign[jn] * xmat[b, i, cls]
                else:
                    xaxis[jn, i] = (
                        xmat[b, i, 0] * jnt_axis[jn, 0]
                        + xmat[b, i, 1] * jnt_axis[jn, 1]
                        + xmat[b, i, 2] * jnt_axis[jn, 2]
                    )
            if kind == SLIDE:
                d = q[a] - qpos0[a]
                for i in range(3):
                    xpos[b, i] += xaxis[jn, i] * d
                continue
            if kind == HINGE and cls < 3:  # columns ca, cb turned about the axis
                theta = jnt_sign[jn] * (q[a] - qpos0[a])
                co, si = math.cos(theta), math.sin(theta)
                ca, cb = (1, 2) if cls == 0 else ((2, 0) if cls == 1 else (0, 1))
                for i in range(3):
                    ra, rb = xmat[b, i, ca], xmat[b, i, cb]
                    xmat[b, i, ca] = co * ra + si * rb
                    xmat[b, i, cb] = co * rb - si * ra
            else:
                if kind == HINGE:  # Rodrigues about the unit axis (as twin.kinematics_tree)
                    theta = q[a] - qpos0[a]
                    co, si = math.cos(theta), math.sin(theta)
                    t = 1.0 - co
                    x, y, z = jnt_unit[jn, 0], jnt_unit[jn, 1], jnt_unit[jn, 2]
                    l00, l01, l02 = co + x * x * t, x * y * t - z * si, x * z * t + y * si
                    l10, l11, l12 = y * x * t + z * si, co + y * y * t, y * z * t - x * si
                    l20, l21, l22 = z * x * t - y * si, z * y * t + x * si, co + z * z * t
                else:
                    quat_to_mat(q[a], q[a + 1], q[a + 2], q[a + 3], local)
                    l00, l01, l02 = local[0, 0], local[0, 1], local[0, 2]
                    l10, l11, l12 = local[1, 0], local[1, 1], local[1, 2]
                    l20, l21, l22 = local[2, 0], local[2, 1], local[2, 2]
                for i in range(3):
                    r0, r1, r2 = xmat[b, i, 0], xmat[b, i, 1], xmat[b, i, 2]
                    xmat[b, i, 0] = r0 * l00 + r1 * l10 + r2 * l20
                    xmat[b, i, 1] = r0 * l01 + r1 * l11 + r2 * l21
                    xmat[b, i, 2] = r0 * l02 + r1 * l12 + r2 * l22
            if jnt_offset[jn]:  # the body's origin from the joint's anchor, turned
                for i in range(3):
                    xpos[b, i] = xanchor[jn, i] - (
                        xmat[b, i, 0] * jnt_pos[jn, 0]
                        + xmat[b, i, 1] * jnt_pos[jn, 1]
                        + xmat[b, i, 2] * jnt_pos[jn, 2]
                    )


@nb.njit(**JIT_INLINE)
def site_position(s, site_body, site_pos, xpos, xmat, pos):
    """World position (3,) of site s."""
    b = site_body[s]
    for i in range(3):
        pos[i] = xpos[b, i] + (
            xmat[b, i, 0] * site_pos[s, 0]
            + xmat[b, i, 1] * site_pos[s, 1]
            + xmat[b, i, 2] * site_pos[s, 2]
        )


@nb.njit(**JIT_INLINE)
def site_frame(s, site_body, site_pos, site_rot, site_turned, xpos, xmat, pos, rot):
    """World position (3,) and rotation (3, 3) of site s."""
    site_position(s, site_body, site_pos, xpos, xmat, pos)
    b = site_body[s]
    if site_turned[s]:
        for i in range(3):
            for j in range(3):
                rot[i, j] = (
                    xmat[b, i, 0] * site_rot[s, 0, j]
                    + xmat[b, i, 1] * site_rot[s, 1, j]
                    + xmat[b, i, 2] * site_rot[s, 2, j]
                )
    else:
        for i in range(3):
            for j in range(3):
                rot[i, j] = xmat[b, i, j]


@nb.njit(**JIT_INLINE)
def rotvec_of_product(ra, rb, out, scratch):
    """Rotation vector of ra @ rb.T into out (3,), angle in [0, pi] (as rotvec_soa: the skew
    part, and the quaternion formula of twin.rotations near pi); scratch a (3, 3)."""
    m = scratch
    for i in range(3):
        for j in range(3):
            m[i, j] = ra[i, 0] * rb[j, 0] + ra[i, 1] * rb[j, 1] + ra[i, 2] * rb[j, 2]
    v0 = 0.5 * (m[2, 1] - m[1, 2])
    v1 = 0.5 * (m[0, 2] - m[2, 0])
    v2 = 0.5 * (m[1, 0] - m[0, 1])
    sin = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    cos = 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0)
    if not cos < -0.9:
        scale = math.atan2(sin, cos) / sin if sin > 1e-300 else 1.0
        out[0], out[1], out[2] = v0 * scale, v1 * scale, v2 * scale
        return
    diag = (m[0, 0] + m[1, 1] + m[2, 2], m[0, 0], m[1, 1], m[2, 2])
    best = 0
    for i in range(1, 4):
        if diag[i] > diag[best]:
            best = i
    if best == 0:
        q = (
            1 + m[0, 0] + m[1, 1] + m[2, 2],
            m[2, 1] - m[1, 2],
            m[0, 2] - m[2, 0],
            m[1, 0] - m[0, 1],
        )
    elif best == 1:
        q = (
            m[2, 1] - m[1, 2],
            1 + m[0, 0] - m[1, 1] - m[2, 2],
            m[0, 1] + m[1, 0],
            m[0, 2] + m[2, 0],
        )
    elif best == 2:
        q = (
            m[0, 2] - m[2, 0],
            m[0, 1] + m[1, 0],
            1 - m[0, 0] + m[1, 1] - m[2, 2],
            m[1, 2] + m[2, 1],
        )
    else:
        q = (
            m[1, 0] - m[0, 1],
            m[0, 2] + m[2, 0],
            m[1, 2] + m[2, 1],
            1 - m[0, 0] - m[1, 1] + m[2, 2],
        )
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    sign = -1.0 if q[0] / norm < 0 else 1.0
    w = min(max(sign * q[0] / norm, -1.0), 1.0)
    x, y, z = sign * q[1] / norm, sign * q[2] / norm, sign * q[3] / norm
    sin_half = math.sqrt(x * x + y * y + z * z)
    if sin_half < 1e-12:
        scale = 2.0 / (1.0 if w == 0 else w)
    else:
        scale = 2.0 * math.atan2(sin_half, w) / sin_half
    out[0], out[1], out[2] = x * scale, y * scale, z * scale


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
    (body_pos, body_rot, body_turned, jnt_pos, jnt_offset, jnt_axis, jnt_unit, jnt_class,
     jnt_sign, qpos0, site_pos, site_rot, turned) = numbers  # fmt: skip
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
    for n in range(qs.shape[0]):
        q = qs[n]
        best, stall = np.inf, 0
        for it in range(max_iter + 1):
            tree(
                q, parent, jnt_adr, jnt_num, jnt_type, jnt_qposadr,
                body_pos, body_rot, body_turned, jnt_pos, jnt_offset, jnt_axis, jnt_unit,
                jnt_class, jnt_sign, qpos0, xpos, xmat, xanchor, xaxis, local,
            )  # fmt: skip
            for e in range(2 * nc):  # the closure sites' frames; rotations for welds only
                if has_weld:
                    site_frame(cl_sites[e], site_body, site_pos, site_rot, turned, xpos, xmat,
                               sp[e], srot[e])  # fmt: skip
                else:
                    site_position(cl_sites[e], site_body, site_pos, xpos, xmat, sp[e])
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
                # the tool's frame, then the targets' positions
                site_frame(out_sites[0], site_body, site_pos, site_rot, turned, xpos, xmat,
                           out_pos[n, 0], out_rot[n])  # fmt: skip
                for e in range(1, out_sites.size):
                    site_position(out_sites[e], site_body, site_pos, xpos, xmat, out_pos[n, e])
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


SCREW_SHIFT, SCREW_TURN, SCREW_HINGE, SCREW_SLIDE = 0, 1, 2, 3  # a parameter's screw kinds


@nb.njit(**JIT)
def screws(xpos, xmat, xanchor, xaxis, kind, element, body, vec, pivot, v, w):
    """The parameters' screws at one configuration into v and w (n, 3), ``v = t - w x o``
    (as twin.parameters.ParameterSet.screws_soa): SCREW_SHIFT a translation along ``vec``
    in body ``body``'s frame, SCREW_TURN a rotation about ``vec`` in that frame (its pivot
    ``pivot`` there), SCREW_HINGE and SCREW_SLIDE joint ``element``'s axis (about its
    anchor, or along it)."""
    for k in range(kind.size):
        c = kind[k]
        for i in range(3):
            v[k, i], w[k, i] = 0.0, 0.0
        if c == SCREW_SLIDE:
            for i in range(3):
                v[k, i] = xaxis[element[k], i]
            continue
        if c == SCREW_HINGE:
            j = element[k]
            w0, w1, w2 = xaxis[j, 0], xaxis[j, 1], xaxis[j, 2]
            o0, o1, o2 = xanchor[j, 0], xanchor[j, 1], xanchor[j, 2]
        else:
            b = body[k]
            t0 = xmat[b, 0, 0] * vec[k, 0] + xmat[b, 0, 1] * vec[k, 1] + xmat[b, 0, 2] * vec[k, 2]
            t1 = xmat[b, 1, 0] * vec[k, 0] + xmat[b, 1, 1] * vec[k, 1] + xmat[b, 1, 2] * vec[k, 2]
            t2 = xmat[b, 2, 0] * vec[k, 0] + xmat[b, 2, 1] * vec[k, 1] + xmat[b, 2, 2] * vec[k, 2]
            if c == SCREW_SHIFT:
                v[k, 0], v[k, 1], v[k, 2] = t0, t1, t2
                continue
            w0, w1, w2 = t0, t1, t2
            o0 = xpos[b, 0] + (
                xmat[b, 0, 0] * pivot[k, 0]
                + xmat[b, 0, 1] * pivot[k, 1]
                + xmat[b, 0, 2] * pivot[k, 2]
            )
            o1 = xpos[b, 1] + (
                xmat[b, 1, 0] * pivot[k, 0]
                + xmat[b, 1, 1] * pivot[k, 1]
                + xmat[b, 1, 2] * pivot[k, 2]
            )
            o2 = xpos[b, 2] + (
                xmat[b, 2, 0] * pivot[k, 0]
                + xmat[b, 2, 1] * pivot[k, 1]
                + xmat[b, 2, 2] * pivot[k, 2]
            )
        w[k, 0], w[k, 1], w[k, 2] = w0, w1, w2
        v[k, 0] = 0.0 - (w1 * o2 - w2 * o1)
        v[k, 1] = 0.0 - (w2 * o0 - w0 * o2)
        v[k, 2] = 0.0 - (w0 * o1 - w1 * o0)


@nb.njit(**JIT)
def jacobian_batch(qs, structure, numbers, closure, dofs, outputs, parameters, pairs, out):
    """The identification Jacobian d(outputs)/d(parameters) at the closed configurations qs
    (N, nq) into out (N, m, n), m = O * (6 if angular else 3), as
    twin.sensitivity_batch._chunk: per configuration the frames (:func:`tree`), the
    parameters' screws (:func:`screws`), the explicit term ``v + w x p`` (and ``w`` for the
    rotation rows) of each (output site, parameter) pair that moves, the outputs' motion
    under each free dof ``jt``, and the implicit term ``z^T c_pi``: the adjoint solve
    ``J^T z = jt`` (as twin.kinematics_adjoint: each closure's block [private | shared |
    identity] eliminated with partial pivoting, its identity columns becoming the row
    transform T; ``U^T w_top = jt_private``; the transposed reduced system;
    ``z_c = T^T [w_top; w_red]``), then ``+-z_c . (v + w x p)`` (and ``+-z_rot . w`` for a
    weld's rotation rows; + for a closure's first site, - for its second) of each (closure
    site, parameter) pair that moves. Square closure systems only (none: a serial chain).

    outputs = (sites (O,), moves (O, n_free) the free dof moves the site, angular);
    parameters = the :func:`screws` arrays; pairs = (closure site, parameter) and (output,
    parameter) pairs that move."""
    parent, jnt_adr, jnt_num, jnt_type, jnt_qposadr, site_body = structure
    (body_pos, body_rot, body_turned, jnt_pos, jnt_offset, jnt_axis, jnt_unit, jnt_class,
     jnt_sign, qpos0, site_pos, _, _) = numbers  # fmt: skip
    cl_sites, cl_rows, cl_off, cl_k, cl_private, shared, moves, _ = closure
    dof_kind, dof_joint, dof_body, dof_col, dof_rot = dofs
    out_sites, out_moves, angular = outputs
    kind, element, body, vec, pivot = parameters
    pair_site, pair_par, out_site, out_par = pairs
    nbody, njnt, n_par = parent.size, jnt_type.size, kind.size
    nc, s, nf = cl_rows.size, shared.size, dof_kind.size
    n_out = out_sites.size
    d = 6 if angular else 3
    m = n_out * d
    kmax = cl_private.shape[1]
    xpos, xmat = np.empty((nbody, 3)), np.empty((nbody, 3, 3))
    xanchor, xaxis = np.empty((njnt, 3)), np.empty((njnt, 3))
    local = np.empty((3, 3))
    sp, pt = np.empty((max(1, 2 * nc), 3)), np.empty((max(1, n_out), 3))
    v, w = np.empty((n_par, 3)), np.empty((n_par, 3))
    axes, anchors = np.empty((max(1, nf), 3)), np.empty((max(1, nf), 3))
    jt = np.empty((max(1, nf), m))
    implicit = np.empty((m, n_par))
    blocks = np.empty((max(1, nc), 6, kmax + s + 6))
    w_top = np.empty((max(1, nc), max(1, kmax), m))
    red = np.empty((max(1, s), max(1, s)))
    aug = np.empty((max(1, s), s + m))
    w_red = np.empty((max(1, s), m))
    rhs_s = np.empty((max(1, s), m))
    z = np.empty((max(1, cl_rows.sum()), m))
    out[:] = 0.0
    for n in range(qs.shape[0]):
        tree(
            qs[n], parent, jnt_adr, jnt_num, jnt_type, jnt_qposadr,
            body_pos, body_rot, body_turned, jnt_pos, jnt_offset, jnt_axis, jnt_unit,
            jnt_class, jnt_sign, qpos0, xpos, xmat, xanchor, xaxis, local,
        )  # fmt: skip
        for e in range(2 * nc):
            site_position(cl_sites[e], site_body, site_pos, xpos, xmat, sp[e])
        for e in range(n_out):
            site_position(out_sites[e], site_body, site_pos, xpos, xmat, pt[e])
        screws(xpos, xmat, xanchor, xaxis, kind, element, body, vec, pivot, v, w)
        for p in range(out_site.size):  # the explicit term
            e, k = out_site[p], out_par[p]
            w0, w1, w2 = w[k, 0], w[k, 1], w[k, 2]
            r = e * d
            out[n, r, k] = v[k, 0] + (w1 * pt[e, 2] - w2 * pt[e, 1])
            out[n, r + 1, k] = v[k, 1] + (w2 * pt[e, 0] - w0 * pt[e, 2])
            out[n, r + 2, k] = v[k, 2] + (w0 * pt[e, 1] - w1 * pt[e, 0])
            if angular:
                out[n, r + 3, k], out[n, r + 4, k], out[n, r + 5, k] = w0, w1, w2
        if nc == 0:
            continue
        dof_axes(xmat, xanchor, xaxis, dof_kind, dof_joint, dof_body, dof_col, axes, anchors)
        for f in range(nf):  # the outputs' motion under each free dof
            a0, a1, a2 = axes[f, 0], axes[f, 1], axes[f, 2]
            for e in range(n_out):
                r = e * d
                for i in range(d):
                    jt[f, r + i] = 0.0
                if out_moves[e, f] == 0:
                    continue
                if not dof_rot[f]:
                    jt[f, r], jt[f, r + 1], jt[f, r + 2] = a0, a1, a2
                    continue
                l0 = pt[e, 0] - anchors[f, 0]
                l1 = pt[e, 1] - anchors[f, 1]
                l2 = pt[e, 2] - anchors[f, 2]
                jt[f, r] = a1 * l2 - a2 * l1
                jt[f, r + 1] = a2 * l0 - a0 * l2
                jt[f, r + 2] = a0 * l1 - a1 * l0
                if angular:
                    jt[f, r + 3], jt[f, r + 4], jt[f, r + 5] = a0, a1, a2
        for j in range(s):
            for q in range(m):
                rhs_s[j, q] = jt[shared[j], q]
        n_red = 0
        for c in range(nc):
            rows, k = cl_rows[c], cl_k[c]
            blk = blocks[c]
            closure_block(
                c, sp, axes, anchors, dof_rot, moves, cl_rows, cl_k, cl_private, shared, blk
            )
            for i in range(rows):
                for t in range(rows):
                    blk[i, k + s + t] = 1.0 if i == t else 0.0
            gauss(blk, rows, k, k + s + rows)
            for i in range(k):  # U^T w_top = jt_private (forward substitution)
                dg = blk[i, i]
                f = cl_private[c, i]
                for q in range(m):
                    acc = jt[f, q]
                    for t in range(i):
                        acc -= blk[t, i] * w_top[c, t, q]
                    w_top[c, i, q] = acc / dg
            for j in range(s):  # the shared equations less the private rows' part
                for i in range(k):
                    bij = blk[i, k + j]
                    for q in range(m):
                        rhs_s[j, q] -= bij * w_top[c, i, q]
            for i in range(k, rows):
                for j in range(s):
                    red[n_red, j] = blk[i, k + j]
                n_red += 1
        if s:  # red^T w_red = rhs_s
            for i in range(s):
                for j in range(s):
                    aug[i, j] = red[j, i]
                for q in range(m):
                    aug[i, s + q] = rhs_s[i, q]
            gauss(aug, s, s, s + m)
            for i in range(s - 1, -1, -1):
                dg = aug[i, i]
                for q in range(m):
                    acc = aug[i, s + q]
                    for t in range(i + 1, s):
                        acc -= aug[i, t] * w_red[t, q]
                    w_red[i, q] = acc / dg
        start = 0
        for c in range(nc):  # z_c = T^T [w_top; w_red_c]
            rows, k = cl_rows[c], cl_k[c]
            blk = blocks[c]
            o = cl_off[c]
            for e in range(rows):
                for q in range(m):
                    z[o + e, q] = 0.0
                for t in range(k):
                    te = blk[t, k + s + e]
                    for q in range(m):
                        z[o + e, q] += te * w_top[c, t, q]
                for t in range(k, rows):
                    te = blk[t, k + s + e]
                    for q in range(m):
                        z[o + e, q] += te * w_red[start + t - k, q]
            start += rows - k
        implicit[:] = 0.0
        for p in range(pair_site.size):
            e, kp = pair_site[p], pair_par[p]
            c = e % nc
            sign = 1.0 if e < nc else -1.0
            w0, w1, w2 = w[kp, 0], w[kp, 1], w[kp, 2]
            u0 = v[kp, 0] + (w1 * sp[e, 2] - w2 * sp[e, 1])
            u1 = v[kp, 1] + (w2 * sp[e, 0] - w0 * sp[e, 2])
            u2 = v[kp, 2] + (w0 * sp[e, 1] - w1 * sp[e, 0])
            o = cl_off[c]
            for q in range(m):
                acc = z[o, q] * u0 + z[o + 1, q] * u1 + z[o + 2, q] * u2
                if cl_rows[c] == 6:
                    acc += z[o + 3, q] * w0 + z[o + 4, q] * w1 + z[o + 5, q] * w2
                implicit[q, kp] += sign * acc
        for q in range(m):
            for k in range(n_par):
                out[n, q, k] -= implicit[q, k]
