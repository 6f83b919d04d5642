"""Per-degree-of-freedom motion axes: site Jacobians of many poses at once, in numpy."""

from __future__ import annotations

import mujoco
import numpy as np

from twin.kinematics.tree import dofs_moving_sites
from twin.mechanism import Mechanism

FREE = int(mujoco.mjtJoint.mjJNT_FREE)
BALL = int(mujoco.mjtJoint.mjJNT_BALL)


class DofAxes:
    """Per-dof motion axes of a model, for Jacobians computed in numpy from frames.

    Built once for a model and a list of sites; every Jacobian is then computed for many
    poses at once from their frames (``xaxis``, ``xanchor``, ``xmat`` and the sites'
    positions), as ``mj_jacSite`` would for one pose."""

    def __init__(self, model: mujoco.MjModel, sites: np.ndarray, free: np.ndarray) -> None:
        nv = model.nv
        free_mask = np.zeros(nv, dtype=bool)
        free_mask[free] = True
        self.joint = model.dof_jntid.copy()
        self.body = model.dof_bodyid.copy()
        self.kind = np.zeros(nv, dtype=int)  # 0 axis from xaxis, 1 world unit, 2 body column
        self.column = np.zeros(nv, dtype=int)
        self.is_rot = np.zeros(nv, dtype=bool)
        for d in range(nv):
            j = self.joint[d]
            jt, k = int(model.jnt_type[j]), d - model.jnt_dofadr[j]
            if jt == FREE:
                self.kind[d], self.column[d], self.is_rot[d] = (
                    (1, k, False) if k < 3 else (2, k - 3, True)
                )
            elif jt == BALL:
                self.kind[d], self.column[d], self.is_rot[d] = 2, k, True
            else:
                self.is_rot[d] = jt == int(mujoco.mjtJoint.mjJNT_HINGE)
        self.mask = dofs_moving_sites(model, sites, np.arange(nv))  # [s, d]: d moves s
        self.pairs = np.nonzero(self.mask & free_mask[None, :])
        self.scatter: list | None = None

    def closure_jacobian(
        self,
        mech: Mechanism,
        xaxis: np.ndarray,
        xanchor: np.ndarray,
        xmat: np.ndarray,
        p: np.ndarray,
        free: np.ndarray,
    ) -> np.ndarray:
        """d(closure residual)/d(free dofs), (N, n_closure, n_free), from frames of N poses.

        ``p`` (N, S, 3) are the positions of the sites given at construction (all first
        sites of the closures, then all second sites); only (site, dof) pairs where the
        dof moves the site are computed, and scattered straight into their rows.
        """
        n = len(p)
        site, dof = self.pairs
        rot_pair = self.is_rot[dof]
        axes, lin = self._motion(xaxis, xanchor, xmat, p, site, dof)
        if self.scatter is None:
            self.scatter = _scatter_plan(mech, site, dof, rot_pair, free)
        out = np.zeros((n, mech.n_closure * len(free)))
        for flat, pick, sign, use_rot in self.scatter:
            vals = (axes if use_rot else lin)[:, pick]  # (N, k, 3)
            out[:, flat] += sign * vals.reshape(n, -1)
        return out.reshape(n, mech.n_closure, len(free))

    def site_jacobian(
        self,
        model: mujoco.MjModel,
        xaxis: np.ndarray,
        xanchor: np.ndarray,
        xmat: np.ndarray,
        p: np.ndarray,
        free: np.ndarray,
    ) -> np.ndarray:
        """Translational Jacobians of the sites w.r.t. the dofs ``free``, (N, S, 3, n_free),
        from frames of N poses and the sites' positions ``p`` (N, S, 3)."""
        n = len(p)
        site, dof = self.pairs
        _, lin = self._motion(xaxis, xanchor, xmat, p, site, dof)
        free_index = -np.ones(model.nv, dtype=int)
        free_index[free] = np.arange(len(free))
        out = np.zeros((n, p.shape[1], 3, len(free)))
        out[:, site, :, free_index[dof]] = np.moveaxis(lin, 1, 0)
        return out

    def _motion(self, xaxis, xanchor, xmat, p, site, dof):
        """(axes, linear velocities) of each (site, dof) pair, each (N, P, 3)."""
        n = len(p)
        joint = self.joint[dof]
        axes = xaxis[:, joint].copy()
        unit = self.kind[dof] == 1
        axes[:, unit] = np.eye(3)[self.column[dof][unit]]
        col = self.kind[dof] == 2
        if np.any(col):
            rot_t = np.swapaxes(xmat.reshape(n, -1, 3, 3), 2, 3)  # rows = frame axes
            axes[:, col] = rot_t[:, self.body[dof][col], self.column[dof][col]]
        rot_pair = self.is_rot[dof]
        lin = axes.copy()
        lever = p[:, site[rot_pair]] - xanchor[:, joint[rot_pair]]
        lin[:, rot_pair] = cross(axes[:, rot_pair], lever)
        return axes, lin


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (cheaper than np.cross on small batched arrays)."""
    return a[..., [1, 2, 0]] * b[..., [2, 0, 1]] - a[..., [2, 0, 1]] * b[..., [1, 2, 0]]


def _scatter_plan(mech, site, dof, rot_pair, free):
    """Index lists that place (site, dof) Jacobian entries into closure rows and free columns."""
    nc = len(mech.closures)
    offsets = np.cumsum([0] + [c.size for c in mech.closures])
    free_index = -np.ones(mech.model.nv, dtype=int)
    free_index[free] = np.arange(len(free))
    plan = []
    for side, sign in ((0, 1.0), (1, -1.0)):
        for use_rot in (False, True):
            rows, cols, pick = [], [], []
            for k in range(len(site)):
                s, d = site[k], dof[k]
                if (s >= nc) != bool(side) or free_index[d] < 0:
                    continue
                ci = s - side * nc
                if use_rot and (mech.closures[ci].kind != "weld" or not rot_pair[k]):
                    continue
                base = offsets[ci] + (3 if use_rot else 0)
                rows += [base, base + 1, base + 2]
                cols += [free_index[d]] * 3
                pick.append(k)
            if pick:
                flat = np.array(rows) * len(free) + np.array(cols)
                plan.append((flat, np.array(pick), sign, use_rot))
    return plan
