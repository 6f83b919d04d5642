"""Forward kinematics of a batch of poses: each pose's whole Newton in machine code."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from twin.kinematics.kernels.elimination import closure_step, dof_axes
from twin.kinematics.kernels.frames import rotvec_of_product, site_frame, site_position, tree
from twin.kinematics.kernels.jit import FREE, JIT


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
