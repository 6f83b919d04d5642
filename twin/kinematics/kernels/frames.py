"""MuJoCo's ``mj_kinematics`` of one pose in machine code: body frames, sites, rotation vectors."""

from __future__ import annotations

import math

import numba as nb

from twin.kinematics.kernels.jit import FREE, HINGE, JIT, JIT_INLINE, SLIDE


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
    xanchor and xaxis (njnt, 3); ``local`` a (3, 3) scratch. As twin.kinematics.tree, a body
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
                if kind == HINGE:  # Rodrigues about the unit axis (as twin.kinematics.tree)
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
