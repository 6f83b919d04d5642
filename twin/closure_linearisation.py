"""First-order starts for the closure solve at nearby parameter values.

At solved configurations ``q`` of parameter values ``pi`` the closure ``c(q, pi) = 0`` moves,
for a parameter change ``d``, to first order by ``dq = -(dc/dq)^-1 (dc/dpi) d`` (the same
implicit-function theorem as the identification Jacobian, one right-hand side per pose).
Starting the Newton solve at ``q + dq`` instead of ``q`` leaves an error of the order of
``|d|^2``: an estimator's small late steps then close in one Newton step or none. Only the
start changes; the solve, its tolerance and its checks are the same.

Built by twin.sensitivity_batch from what the identification Jacobian computed anyway (the
frames at ``q``, the parameters' screws, the closure sites).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.kinematics_adjoint import forward_solve_factored
from twin.kinematics_fast import fast_kinematics, integrate_soa, one_blas_thread
from twin.kinematics_reduced import cross_soa
from twin.kinematics_tree import TreeFrames
from twin.mechanism import Mechanism

MAX_START_STEP = 0.05  # a predicted start moving any free coordinate further (m, rad) is not used


@dataclass(frozen=True)
class ClosurePart:
    """One chunk of configurations: frames, closure sites and screws at the solution.

    A parameter ``k`` moves a site at ``p`` that it affects by ``v_k + w_k x p``."""

    frames: TreeFrames
    site_pos: np.ndarray  # (3, 2C, n) closure sites, first sites then second
    factor: list[np.ndarray] | None  # a square system's elimination (kinematics_adjoint)
    v: np.ndarray  # (3, n_par, n)
    w: np.ndarray  # (3, n_par, n)
    affected_a: np.ndarray  # (C, n_par) float: the parameter moves the closure's first site
    affected_b: np.ndarray  # (C, n_par) ... its second site


@dataclass(frozen=True)
class ClosureLinearisation:
    """The closure system of ``mech`` (parameter ``values`` injected) at solved ``qpos``."""

    mech: Mechanism
    values: np.ndarray  # (n_par,)
    qpos: np.ndarray  # (N, nq)
    parts: tuple[tuple[slice, ClosurePart], ...]

    def fits(self, commands: np.ndarray) -> bool:
        """Whether ``commands`` (N, A) are the ones these configurations were solved for."""
        cmd = self.qpos[:, self.mech.actuator_qpos]
        return commands.shape == cmd.shape and np.array_equal(commands, cmd)

    def start(self, values: np.ndarray) -> np.ndarray | None:
        """Configurations (N, nq) moved to first order towards the closure at ``values``;
        None when the predicted move is large (then the solved ``qpos`` are the better start)."""
        fk = fast_kinematics(self.mech)
        cs = fk.closure
        delta = np.asarray(values, dtype=float) - self.values
        q = np.ascontiguousarray(self.qpos.T)  # (nq, N)
        with one_blas_thread():
            steps = []
            for sl, part in self.parts:
                rhs = -self._closure_change(part, delta, cs.row_offset, cs.n_closure)
                if part.factor is not None:
                    steps.append((sl, forward_solve_factored(cs, part.factor, rhs)))
                else:
                    mats = cs.matrices(part.frames, part.site_pos, rhs[:, None])
                    steps.append((sl, cs.solve(mats)[:, 0]))  # (n_free, n)
            step = np.empty((len(cs.free), q.shape[1]))
            for sl, s in steps:
                step[:, sl] = s
            if not np.all(np.isfinite(step)) or np.max(np.abs(step)) > MAX_START_STEP:
                return None
            integrate_soa(fk, q, step)
        return np.ascontiguousarray(q.T)

    def _closure_change(
        self, part: ClosurePart, delta: np.ndarray, row_offset: np.ndarray, n_closure: int
    ) -> np.ndarray:
        """(dc/dpi) delta, (n_closure, n) in residual row order."""
        da, db = part.affected_a * delta, part.affected_b * delta  # (C, n_par)
        va, vb = np.einsum("ck,ikn->icn", da, part.v), np.einsum("ck,ikn->icn", db, part.v)
        wa, wb = np.einsum("ck,ikn->icn", da, part.w), np.einsum("ck,ikn->icn", db, part.w)
        nc = da.shape[0]
        pos = va + cross_soa(wa, part.site_pos[:, :nc]) - vb - cross_soa(wb, part.site_pos[:, nc:])
        out = np.empty((n_closure, pos.shape[-1]))
        for i, c in enumerate(self.mech.closures):
            r0 = row_offset[i]
            out[r0 : r0 + 3] = pos[:, i]
            if c.kind == "weld":
                out[r0 + 3 : r0 + 6] = wa[:, i] - wb[:, i]
        return out
