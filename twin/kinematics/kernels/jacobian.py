"""The identification Jacobian of a batch of poses: parameter screws and the adjoint solve."""

from __future__ import annotations

import numba as nb
import numpy as np

from twin.kinematics.kernels.elimination import closure_block, dof_axes, gauss
from twin.kinematics.kernels.frames import site_position, tree
from twin.kinematics.kernels.jit import JIT

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
    twin.kinematics.sensitivity_batch._chunk: per configuration the frames (:func:`tree`), the
    parameters' screws (:func:`screws`), the explicit term ``v + w x p`` (and ``w`` for the
    rotation rows) of each (output site, parameter) pair that moves, the outputs' motion
    under each free dof ``jt``, and the implicit term ``z^T c_pi``: the adjoint solve
    ``J^T z = jt`` (as twin.kinematics.adjoint: each closure's block [private | shared |
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
