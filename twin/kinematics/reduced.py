"""The closure Jacobian of many configurations and its solve, by elimination per closure.

A closed chain's closure Jacobian is sparse in a way the MJCF fixes: a limb's passive joints
move only the site of their own closure (they are *private* to it), while a few degrees of
freedom (a moving platform, a shared limb) appear in several closures (*shared*). Eliminating
each closure's private columns first (Gaussian elimination with partial pivoting on that
closure's rows) leaves a small *reduced* system over the shared columns; its solution, put
back, gives the private ones. In exact arithmetic this is the same solution as the full
system's (and the same least-squares solution when there are more equations than unknowns),
at a fraction of the cost: for the hexapod six 6 x 5 eliminations and one 6 x 6 solve instead
of a 36 x 36 one.

Everything is read from the model (which dof moves which site, joint kinds), so every machine
goes through this one code path; a structure the elimination does not fit (a closure with more
private columns than rows, a dof in no closure) treats every dof as shared, which is the full
system. Arrays are "structure of arrays" with the configurations last (twin.kinematics.tree).
Elimination is numpy vectorised over configurations (twin.kinematics.small_systems): no
per-configuration
LAPACK call. Pivots are static (chosen once by partial pivoting at the home configuration, for
each closure and for the square reduced system) and checked in every solve; a system whose
pivot fails the threshold test is redone by Householder reflections.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.kinematics.small_systems import (  # eliminate_static: the tests replace it here
    back_substitute,
    eliminate,
    eliminate_static,
    pivot_order,
    solve_dense,
    solve_square,
)
from twin.kinematics.tree import FREE, HINGE, TreeFrames, as_index, dofs_moving_sites
from twin.mechanism import Mechanism

BALL = int(mujoco.mjtJoint.mjJNT_BALL)
AXIS_JOINT, AXIS_WORLD, AXIS_BODY = 0, 1, 2  # a dof's axis: joint xaxis, world e_k, body column


@dataclass(frozen=True)
class EntryClass:
    """Jacobian entries (closure, dof) of one kind: how each is computed and where it goes."""

    rot: bool  # rotational dof: linear part axis x lever, angular part the axis
    ma: float  # the dof moves the closure's first site (1) or not (0)
    mb: float  # ... its second site
    dof: np.ndarray  # positions into the free dofs
    closure: np.ndarray  # closure ids
    site_a: np.ndarray  # positions into the closure-site list (first sites then second)
    site_b: np.ndarray
    # per group: (group, component row 0-5, entry, column, slot) of each value written
    dest: tuple[tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray], ...]


@dataclass(frozen=True)
class ClosureGroup:
    """Closures with the same number of rows and private columns, eliminated together."""

    closures: np.ndarray  # closure ids
    rows: int  # equations per closure (3 connect, 6 weld)
    k: int  # private columns per closure
    private: np.ndarray  # (G, k) positions into the free dofs


class ClosureStructure:
    """Which dof moves which closure site, and the elimination order, for one mechanism."""

    def __init__(self, mech: Mechanism) -> None:
        m = mech.model
        self.free = mech.free_dofs()
        self.n_closure = mech.n_closure
        a = np.array([c.site_a for c in mech.closures], dtype=int)
        b = np.array([c.site_b for c in mech.closures], dtype=int)
        self.sites = np.concatenate([a, b])
        nc = len(mech.closures)
        self.row_offset = np.cumsum([0] + [c.size for c in mech.closures])[:-1]
        self.weld = np.array([c.kind == "weld" for c in mech.closures], dtype=bool)
        self._read_dofs(m)
        moves = dofs_moving_sites(m, self.sites, self.free)  # (2 C, n_free)
        self.site_moves = moves
        entries = []  # (closure, dof, ma, mb, rot)
        touch = np.zeros((nc, len(self.free)), dtype=bool)
        for c in range(nc):
            for f in range(len(self.free)):
                ma, mb = bool(moves[c, f]), bool(moves[nc + c, f])
                rot = bool(self.dof_rot[f])
                if not (ma or mb) or (ma and mb and not rot):
                    continue  # no entry, or a translation of both sites alike
                entries.append((c, f, ma, mb, rot))
                touch[c, f] = True
        self._partition(mech, touch)
        self._plan_entries(entries, nc)

    # ----------------------------------------------------------------- structure
    def _read_dofs(self, m: mujoco.MjModel) -> None:
        f = self.free
        self.dof_joint = m.dof_jntid[f].copy()
        self.dof_body = m.dof_bodyid[f].copy()
        self.dof_kind = np.full(len(f), AXIS_JOINT)
        self.dof_col = np.zeros(len(f), dtype=int)
        self.dof_rot = np.zeros(len(f), dtype=bool)
        for i, d in enumerate(f):
            j = int(m.dof_jntid[d])
            jt, k = int(m.jnt_type[j]), int(d - m.jnt_dofadr[j])
            if jt == FREE:
                self.dof_kind[i] = AXIS_WORLD if k < 3 else AXIS_BODY
                self.dof_col[i] = k % 3
                self.dof_rot[i] = k >= 3
            elif jt == BALL:
                self.dof_kind[i], self.dof_col[i], self.dof_rot[i] = AXIS_BODY, k, True
            else:
                self.dof_rot[i] = jt == HINGE
        self.simple = self.dof_kind == AXIS_JOINT
        self.simple_joint = as_index(self.dof_joint[self.simple])

    def _partition(self, mech: Mechanism, touch: np.ndarray) -> None:
        """Private columns per closure, shared columns, and groups of like closures."""
        nc, nf = touch.shape
        count = touch.sum(axis=0)
        owner = np.where(count == 1, np.argmax(touch, axis=0), -1)
        sizes = np.array([c.size for c in mech.closures], dtype=int)
        private = [np.flatnonzero(owner == c) for c in range(nc)]
        fits = all(len(private[c]) <= sizes[c] for c in range(nc)) and np.all(count > 0)
        if not fits:  # no elimination: every dof shared, the reduced system is the full one
            private = [np.zeros(0, dtype=int) for _ in range(nc)]
        is_private = np.zeros(nf, dtype=bool)
        for p in private:
            is_private[p] = True
        self.shared = np.flatnonzero(~is_private)
        self.eliminates = fits
        kinds: dict[tuple[int, int], list[int]] = {}
        for c in range(nc):
            kinds.setdefault((int(sizes[c]), len(private[c])), []).append(c)
        self.groups = []
        self.group_of = np.zeros(nc, dtype=int)
        self.slot_of = np.zeros(nc, dtype=int)
        for g, ((rows, k), members) in enumerate(sorted(kinds.items())):
            priv = np.array([private[c] for c in members], dtype=int).reshape(len(members), k)
            self.groups.append(ClosureGroup(np.array(members), rows, k, priv))
            self.group_of[members] = g
            self.slot_of[members] = np.arange(len(members))
        # row order of each closure's equations in its matrix: the static pivots of the
        # elimination (ClosureStructure.order_rows); the identity until chosen
        self.rank = [np.tile(np.arange(g.rows), (len(g.closures), 1)) for g in self.groups]
        self.reduced_order = np.arange(len(self.shared))  # the reduced system's, likewise
        self.reduced_order_t = np.arange(len(self.shared))  # its transpose's (adjoint solves)
        self._plans: dict[int, tuple[list, list[np.ndarray]]] = {}  # see _scatter_plan
        self.square = fits and nf == self.n_closure
        shared_pos = -np.ones(nf, dtype=int)
        shared_pos[self.shared] = np.arange(len(self.shared))
        self.column = np.zeros((nc, nf), dtype=int)  # column of dof f in closure c's matrix
        for c in range(nc):
            g = self.groups[self.group_of[c]]
            for i, f in enumerate(private[c]):
                self.column[c, f] = i
            self.column[c, self.shared] = g.k + np.arange(len(self.shared))

    def _plan_entries(self, entries: list, nc: int) -> None:
        classes: dict[tuple[bool, bool, bool], list] = {}
        for e in entries:
            classes.setdefault((e[4], e[2], e[3]), []).append(e)
        self.classes = []
        for (rot, ma, mb), items in sorted(classes.items()):
            cl = np.array([e[0] for e in items])
            dof = np.array([e[1] for e in items])
            dest = []
            for g in range(len(self.groups)):
                pick = np.flatnonzero(self.group_of[cl] == g)
                if not pick.size:
                    continue
                comp, pk = [], []
                for c in range(3):  # linear rows; angular rows of welds (rotational dofs)
                    comp.append(np.full(pick.size, c))
                    pk.append(pick)
                if rot:
                    weld = pick[self.weld[cl[pick]]]
                    for c in range(3):
                        comp.append(np.full(weld.size, 3 + c))
                        pk.append(weld)
                comp_a, pk_a = np.concatenate(comp), np.concatenate(pk)
                col = self.column[cl[pk_a], dof[pk_a]]
                dest.append((g, comp_a, pk_a, col, self.slot_of[cl[pk_a]]))
            self.classes.append(
                EntryClass(rot, float(ma), float(mb), dof, cl, cl, nc + cl, tuple(dest))
            )
        # residual rows (closure-major: 3 position rows, then 3 rotation rows of a weld)
        self.rhs_rows = []
        for grp in self.groups:
            src, dst = [], []
            for i, c in enumerate(grp.closures):
                for row in range(grp.rows):
                    src.append(self.row_offset[c] + row)
                    dst.append((row, i))
            self.rhs_rows.append((np.array(src), np.array(dst)))

    # ----------------------------------------------------------------- numbers
    def dof_axes(self, frames: TreeFrames) -> tuple[np.ndarray, np.ndarray]:
        """World axes (3, n_free, N) and anchors (3, n_free, N) of the free dofs."""
        n = frames.xpos.shape[-1]
        axes = np.empty((3, len(self.free), n))
        axes[:, self.simple] = frames.xaxis[:, self.simple_joint]
        world = self.dof_kind == AXIS_WORLD
        if np.any(world):
            axes[:, world] = np.eye(3)[:, self.dof_col[world], None]
        body = self.dof_kind == AXIS_BODY
        if np.any(body):
            axes[:, body] = frames.xmat[:, self.dof_col[body], self.dof_body[body]]
        anchors = frames.xanchor[:, self.dof_joint]
        return axes, anchors

    def matrices(
        self,
        frames: TreeFrames,
        site_pos: np.ndarray,
        rhs: np.ndarray,
        part: np.ndarray | None = None,
    ) -> list[np.ndarray]:
        """Per group the augmented matrix (rows, k + s + m, G, N): [private | shared | rhs].

        ``site_pos`` (3, 2 C, N) are the closure sites' positions (first sites, then second);
        ``rhs`` (n_closure, m, N) the right-hand sides in residual row order; ``part`` (a
        mask over the N configurations) keeps only some of them."""
        axes, anchors = self.dof_axes(frames)
        if part is not None:
            axes, anchors = axes[..., part], anchors[..., part]
            site_pos, rhs = site_pos[..., part], rhs[..., part]
        n, m_rhs = rhs.shape[-1], rhs.shape[1]
        s = len(self.shared)
        scatter, fixed = self._scatter_plan(m_rhs)
        mats = [np.empty((g.rows, g.k + s + m_rhs, len(g.closures), n)) for g in self.groups]
        for mat, (flat, value) in zip(mats, fixed, strict=True):  # zeros and constants
            mat.reshape(-1, n)[flat] = value[:, None]
        for ec, plan in zip(self.classes, scatter, strict=True):
            if plan is None:  # constant entries, already written
                continue
            vals = self._values(ec, axes, anchors, site_pos).reshape(-1, n)
            for g, flat, src in plan:
                mats[g].reshape(-1, n)[flat] = vals[src]
        for g, (src, dst) in enumerate(self.rhs_rows):
            grp = self.groups[g]
            mats[g][self.rank[g][dst[:, 1], dst[:, 0]], grp.k + s :, dst[:, 1]] = rhs[src]
        return mats

    def _scatter_plan(self, m_rhs: int) -> tuple[list, list[tuple[np.ndarray, np.ndarray]]]:
        """Where :meth:`matrices` puts each entry class's values, for ``m_rhs`` right-hand
        sides: per class (group, flat rows of the matrix, rows of the values), or None for a
        class whose values are constant (a free joint's translations along world axes);
        per group the flat rows and values of every constant entry (those and the
        structural zeros). Kept: it depends only on the structure and the static pivots."""
        found = self._plans.get(m_rhs)
        if found is not None:
            return found
        s = len(self.shared)
        written = [
            np.zeros((g.rows, g.k + s + m_rhs, len(g.closures)), dtype=bool) for g in self.groups
        ]
        const_flat: list[list[np.ndarray]] = [[] for _ in self.groups]
        const_value: list[list[np.ndarray]] = [[] for _ in self.groups]
        scatter = []
        for ec in self.classes:
            constant = not ec.rot and np.all(self.dof_kind[ec.dof] == AXIS_WORLD)
            values = (ec.ma - ec.mb) * np.eye(3)[:, self.dof_col[ec.dof]] if constant else None
            plan = []
            for g, comp, pk, col, slot in ec.dest:
                grp = self.groups[g]
                ncol, ng = grp.k + s + m_rhs, len(grp.closures)
                rows = self.rank[g][slot, comp]
                flat = (rows * ncol + col) * ng + slot
                if constant:
                    const_flat[g].append(flat)
                    const_value[g].append(values[comp, pk])
                else:
                    plan.append((g, flat, comp * len(ec.dof) + pk))
                written[g][rows, col, slot] = True
            scatter.append(None if constant else plan)
        for g, (_, dst) in enumerate(self.rhs_rows):
            written[g][self.rank[g][dst[:, 1], dst[:, 0]], self.groups[g].k + s :, dst[:, 1]] = True
        fixed = []
        for g, w in enumerate(written):
            zero = np.flatnonzero(~w.reshape(-1))
            flat = np.concatenate([zero, *const_flat[g]])
            value = np.concatenate([np.zeros(zero.size), *const_value[g]])
            fixed.append((flat, value))
        self._plans[m_rhs] = (scatter, fixed)
        return scatter, fixed

    def dense(self, frames: TreeFrames, site_pos: np.ndarray) -> np.ndarray:
        """The full closure Jacobian (N, n_closure, n_free) w.r.t. the free dofs, rows in
        residual order (for solves with many right-hand sides: LAPACK on the adjoint)."""
        axes, anchors = self.dof_axes(frames)
        n, nf = axes.shape[-1], len(self.free)
        out = np.zeros((self.n_closure * nf, n))
        for ec in self.classes:
            vals = self._values(ec, axes, anchors, site_pos)
            for _, comp, pk, _, _ in ec.dest:
                rows = self.row_offset[ec.closure[pk]] + comp
                out[rows * nf + ec.dof[pk]] = vals[comp, pk]
        return out.reshape(self.n_closure, nf, n).transpose(2, 0, 1)

    def _values(
        self, ec: EntryClass, axes: np.ndarray, anchors: np.ndarray, site_pos: np.ndarray
    ) -> np.ndarray:
        """Linear rows (and angular rows of rotational dofs) of one entry class, (3|6, E, N)."""
        w = axes[:, ec.dof]
        sign = ec.ma - ec.mb
        if not ec.rot:
            return w if sign == 1.0 else sign * w
        out = np.empty((6, *w.shape[1:]))
        if ec.ma and ec.mb:
            cross_soa(w, site_pos[:, ec.site_a] - site_pos[:, ec.site_b], out[:3])
        else:
            lever = site_pos[:, ec.site_a if ec.ma else ec.site_b] - anchors[:, ec.dof]
            if sign == 1.0:
                cross_soa(w, lever, out[:3])
            else:  # w x (-lever) = lever x w, the same numbers
                cross_soa(lever, w, out[:3])
        np.multiply(w, sign, out=out[3:])
        return out

    def order_rows(self, frames: TreeFrames, site_pos: np.ndarray) -> None:
        """Choose the static pivots at one configuration (``frames`` of N = 1, e.g. home):
        each closure's rows by partial pivoting on its private columns, then the rows of the
        square reduced system by partial pivoting on it (and on its transpose, for the
        adjoint solves of twin.kinematics.adjoint)."""
        rhs = np.zeros((self.n_closure, 1, 1))
        mats = self.matrices(frames, site_pos, rhs)
        for g, (grp, mat) in enumerate(zip(self.groups, mats, strict=True)):
            for slot in range(len(grp.closures)):
                order = pivot_order(mat[:, : grp.k, slot, 0], grp.k)
                self.rank[g][slot, order] = np.arange(grp.rows)
        self._plans.clear()  # the scatter plans follow the new row order
        s = len(self.shared)
        if self.square and s:
            mats = self.matrices(frames, site_pos, rhs)
            self.eliminate_groups(mats)
            red = self._reduced(mats)
            if red.shape[0] == s:
                self.reduced_order = pivot_order(red[:, :s, 0], s)
                self.reduced_order_t = pivot_order(red[:, :s, 0].T, s)

    def eliminate_groups(
        self, mats: list[np.ndarray], rebuild: Callable[[], list[np.ndarray]] | None = None
    ) -> None:
        """Eliminate every closure's private columns, in place on ``matrices``' output:
        static pivots (Householder where one is too small) for square systems, Householder
        for least squares (orthogonal, so the reduced rows keep the least-squares answer).

        The systems whose static pivots are refused are redone from their original
        matrices: a copy kept beforehand, or, when given, ``rebuild()`` (the same
        ``matrices`` again), called only if a pivot is refused, which saves the copy."""
        fresh = None
        for gi, (g, mat) in enumerate(zip(self.groups, mats, strict=True)):
            flat = mat.reshape(g.rows, mat.shape[1], -1)
            if self.square:
                saved = flat.copy() if rebuild is None else None
                ok = eliminate_static(flat, g.k)
                if not np.all(ok):
                    if saved is None:
                        fresh = rebuild() if fresh is None else fresh
                        saved = fresh[gi].reshape(flat.shape)
                    again = saved[..., ~ok]
                    eliminate(again, g.k)
                    flat[..., ~ok] = again
            else:
                eliminate(flat, g.k)

    def _reduced(self, mats: list[np.ndarray]) -> np.ndarray:
        """The reduced rows (rows after elimination, s + m, N) over the shared columns."""
        n = mats[0].shape[-1]
        reduced = []
        for g, mat in zip(self.groups, mats, strict=True):
            red = mat[g.k :, g.k :]  # (rows - k, s + m, G, N)
            reduced.append(np.moveaxis(red, 2, 1).reshape(-1, red.shape[1], n))
        return np.concatenate(reduced)

    def solve(
        self, mats: list[np.ndarray], rebuild: Callable[[], list[np.ndarray]] | None = None
    ) -> np.ndarray:
        """Solutions (n_free, m, N) of the systems ``matrices`` assembled (in place on them):
        square reduced systems by static pivots (Householder where one is refused), others
        by Householder (least squares); ``rebuild`` as in :meth:`eliminate_groups`."""
        s = len(self.shared)
        n = mats[0].shape[-1]
        m_rhs = mats[0].shape[1] - self.groups[0].k - s
        self.eliminate_groups(mats, rebuild)
        out = np.empty((len(self.free), m_rhs, n))
        if s:
            red = self._reduced(mats)
            if red.shape[0] == s:
                x_s = solve_square(red[self.reduced_order])
            else:
                x_s = solve_dense(red, s)
            out[self.shared] = x_s
        else:
            x_s = np.zeros((0, m_rhs, n))
        for g, mat in zip(self.groups, mats, strict=True):
            if not g.k:
                continue
            top = mat[: g.k, g.k + s :] - np.einsum(
                "ktgn,tmn->kmgn", mat[: g.k, g.k : g.k + s], x_s
            )
            x = back_substitute(mat[: g.k, : g.k], top)  # (k, m, G, N)
            out[g.private.T] = np.moveaxis(x, 2, 1)
        return out


def cross_soa(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Cross product over the first axis (3, ...) (into ``out`` when given)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape)) if out is None else out
    tmp = np.empty(out.shape[1:])
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        np.multiply(a[j], b[k], out=out[i])
        np.multiply(a[k], b[j], out=tmp)
        out[i] -= tmp
    return out
