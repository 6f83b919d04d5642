"""Which member of an exactly redundant group to fix, and who its true partners are.

When the readings cannot separate some parameters (one reflector on a 6R arm: joint 6's zero
and the reflector's offset in the plane normal to joint 6; two parallel joints' offsets along
their axes; the base joints of a platform and the tracker registration), the data fix only
their combination and any one member may be held at zero. Which one matters to a user: the
estimates of the others absorb it. A pivoted QR chooses by column norms, blind to the data,
and can keep a joint zero that must then turn by tens of degrees to play a reflector's offset.

Here the choice is made on the data: the minimum-norm solution of the linearised problem
(parameters measured in their physical ranges, ``1 mm`` and ``0.1 deg`` by default) plus any
null-space motion is an exact fit, and fixing a set F of members means moving along the null
space until those members are zero. F is chosen greedily, one member per null dimension, so
that the move, and so the estimates, stay smallest. The partners of a fixed member are the
parameters of the null direction that carries it (the combination the data cannot tell from
it); whether the registration takes part is read from the unprojected Jacobian.

Every quantity used is independent of the null-space basis the SVD returns, and ties (within
``TIE``, relative) fix the later parameter in declared order, so the choice is the same on
every platform.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from calib.analysis.identifiability import IdentifiabilityReport, scaled_jacobian
from twin.mechanism import Mechanism
from twin.parameters import Parameter

TIE = 1e-6
MEMBER_RTOL = 1e-6  # a null-space component below this fraction of the largest is no member
REGISTRATION_RTOL = 1e-6  # a null direction moving the readings by more: registration takes part


@dataclass(frozen=True)
class Redundancy:
    fixed: tuple[int, ...]  # parameter indices held at their start values, ascending
    partners: dict[int, tuple[int, ...]]  # fixed index -> its partners, strongest first
    with_registration: dict[int, bool]  # fixed index -> the registration takes part


def null_basis(a_u: np.ndarray, n_null: int) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal null basis (n, d) of ``a_u`` (its ``n_null`` weakest right singular
    vectors) and the minimum-norm solution operator's pieces (V1, S1) of the rest."""
    m, n = a_u.shape
    # every right vector, also for m < n, without the (m, m) left factor of a full SVD: the
    # right vectors of a tall matrix are those of its triangular factor (n, n)
    small = np.linalg.qr(a_u, mode="r") if m > n else a_u
    _, s, vt = np.linalg.svd(small, full_matrices=True)
    keep = n - n_null
    return vt[keep:].T, (vt[:keep].T, s[:keep])


class _FixedSpan:
    """The span of the null rows ``v0[fixed]`` kept as it grows one row at a time: an
    orthonormal basis ``q`` (k, d) of it (Gram-Schmidt, twice), the rows of ``v0`` with that
    span taken out, and ``c`` the smallest move zeroing the minimum-norm solution ``u`` at the
    fixed rows (``v0[fixed] c = u[fixed]``, solved by forward substitution on the triangular
    factor). Each added row costs O(n d), where solving the fixed set afresh took an SVD and a
    least-squares solve of (k, d) per choice."""

    def __init__(self, v0: np.ndarray, u: np.ndarray) -> None:
        self.v0, self.u = v0, u
        d = v0.shape[1]
        self.q = np.zeros((0, d))
        self.outside = v0.copy()
        self.y = np.zeros(0)  # c's coordinates in q
        self.c = np.zeros(d)

    def add_all(self, rows: list[int]) -> None:
        """Rows added at once (to an empty span) by one QR factorisation, ``v0[rows] = L q``
        with ``L`` lower triangular; one by one where they are not clearly independent."""
        if len(self.q) or not 0 < len(rows) <= self.v0.shape[1]:
            for j in rows:
                self.add(j)
            return
        qt, r = np.linalg.qr(self.v0[rows].T)
        diag = np.abs(np.diag(r))
        if not np.all(diag > 1e-8 * max(1.0, float(diag.max()))):
            for j in rows:
                self.add(j)
            return
        self.q = qt.T
        self.y = np.linalg.solve(r.T, self.u[rows])
        self.c = self.y @ self.q
        self.outside = self.v0 - (self.v0 @ qt) @ self.q

    def add(self, j: int) -> None:
        row = self.v0[j]
        along = self.q @ row
        r = row - along @ self.q
        again = self.q @ r  # a second pass keeps q orthonormal to round-off
        r -= again @ self.q
        along = along + again
        size = float(np.linalg.norm(r))
        if not size > 0:  # in the span already: nothing new to hold
            return
        qn = r / size
        self.y = np.append(self.y, (self.u[j] - along @ self.y) / size)
        self.q = np.vstack([self.q, qn])
        self.c = self.y @ self.q
        self.outside -= np.outer(self.outside @ qn, qn)


def _next_fixed(span: _FixedSpan, fixed: list[int], member: np.ndarray, norms: np.ndarray) -> int:
    """The parameter whose fixing, beside ``fixed``, needs the smallest null-space move of the
    minimum-norm solution ``u`` (ties within TIE: the later one); -1 when none removes a new
    null dimension. All candidates at once: with ``c`` the smallest move zeroing ``u`` at
    ``fixed`` and ``p_j`` the part of row j of ``v0`` outside the fixed rows' span, fixing j
    as well moves by sqrt(|c|^2 + (u_j - v0_j . c)^2 / |p_j|^2) (a Schur complement), which is
    what solving each candidate's least-squares problem gave, in O(n d) instead of O(n d^3)."""
    c, outside, v0, u = span.c, span.outside, span.v0, span.u
    left = np.linalg.norm(outside, axis=1)
    new = member & (left > MEMBER_RTOL * norms)
    new[fixed] = False
    if not new.any():
        return -1
    with np.errstate(divide="ignore", invalid="ignore"):
        cost = np.sqrt(float(c @ c) + (u - v0 @ c) ** 2 / left**2)
    best, best_cost = -1, np.inf
    for j in np.flatnonzero(new):
        if cost[j] <= best_cost * (1 + TIE) + 1e-300:
            best, best_cost = int(j), min(float(cost[j]), best_cost)  # ties: the later one
    return best


def choose_fixed(
    jac: np.ndarray,
    residual: np.ndarray,
    ranges: np.ndarray,
    n_null: int,
    zero: np.ndarray,
    unprojected: np.ndarray | None = None,
) -> Redundancy:
    """The members to fix (one per null dimension) for the linearised problem
    ``jac @ dx = residual`` (m, n), each parameter measured in its physical range
    ``ranges`` (n,); ``zero`` marks columns with no effect (always fixed). ``unprojected``:
    the Jacobian before the registration was projected out of ``jac`` (tracker frame)."""
    if n_null <= 0:
        return Redundancy((), {}, {})
    a_u = jac * ranges
    a_u[:, zero] = 0.0
    v0, (v1, s1) = null_basis(a_u, n_null)
    u = v1 @ ((a_u @ v1).T @ residual / s1**2)  # minimum-norm solution, range units
    # the columns' own scale must not decide: members are read from the null vectors
    norms = np.linalg.norm(v0, axis=1)
    member = norms > MEMBER_RTOL * norms.max()
    fixed: list[int] = [int(j) for j in np.flatnonzero(zero)]
    span = _FixedSpan(v0, u)
    span.add_all(fixed)
    while len(fixed) < n_null:
        best = _next_fixed(span, fixed, member, norms)
        if best < 0:
            break
        fixed.append(best)
        span.add(best)
    fixed_arr = np.array(sorted(fixed), dtype=int)
    partners: dict[int, tuple[int, ...]] = {}
    with_reg: dict[int, bool] = {}
    # the null direction that moves each fixed member alone (one solve for all of them)
    directions = v0 @ np.linalg.lstsq(v0[fixed_arr], np.eye(len(fixed_arr)), rcond=None)[0]
    held = {int(j) for j in fixed_arr}
    for k, j in enumerate(fixed_arr):
        if zero[j]:
            partners[int(j)], with_reg[int(j)] = (), False
            continue
        direction = directions[:, k]
        size = np.abs(direction)
        # the candidates above the threshold first (a set, not the array, for membership)
        big = np.flatnonzero(size > MEMBER_RTOL * size.max())
        others = [int(i) for i in big[np.argsort(-size[big], kind="stable")] if int(i) not in held]
        partners[int(j)] = tuple(others)
        moved = 0.0
        if unprojected is not None:
            step = direction * ranges
            moved = float(np.linalg.norm(unprojected @ step))
            moved /= max(float(np.linalg.norm(unprojected[:, j] * ranges[j])), 1e-300)
        with_reg[int(j)] = moved > REGISTRATION_RTOL
    return Redundancy(tuple(int(j) for j in fixed_arr), partners, with_reg)


@dataclass(frozen=True)
class Explainer:
    """Says why a redundant group is one, where the mechanism shows it."""

    mech: Mechanism | None
    parameters: tuple[Parameter, ...]

    def __call__(self, members: list[int]) -> str:
        if self.mech is None or not self.parameters:
            return ""
        kinds = [self.parameters[i].kind for i in members]
        zeros = [self.parameters[i] for i in members if self.parameters[i].kind == "joint_zero"]
        if (
            self.mech.n_targets == 1
            and len(zeros) == 1
            and kinds.count("site_pos") == len(members) - 1
            and len(members) > 1
        ):
            return (
                f"; one reflector cannot separate a rotation of joint {zeros[0].element} from "
                "an offset of the reflector in the plane normal to that joint"
            )
        return ""


def with_choice(
    report: IdentifiabilityReport,
    red: Redundancy,
    jac: np.ndarray,
    explain: Explainer,
    with_registration: str,
) -> tuple[IdentifiabilityReport, tuple[str, ...]]:
    """The report with the fixed set of ``red`` and reasons naming the partners; ``jac`` the
    Jacobian the report was made of (the registration projected out); ``with_registration``
    the reason of a member redundant with the registration alone."""
    names = report.names
    why: dict[str, str] = {}
    redundant = []
    for j in red.fixed:
        name = names[j]
        partners = [names[i] for i in red.partners[j]]
        if not partners and not red.with_registration[j]:
            why[name] = report.unidentifiable.get(name, "has no effect on the measurements")
            continue
        if not partners:
            why[name] = with_registration
            redundant.append(name)
            continue
        shown = ", ".join(partners[:4]) + (" ..." if len(partners) > 4 else "")
        with_reg = " and the tracker registration" if red.with_registration[j] else ""
        why[name] = (
            f"redundant with {shown}{with_reg}: the readings cannot tell its effect from "
            "theirs; fixed at 0 as the member whose removal keeps the estimates smallest"
            + explain([j, *red.partners[j]])
        )
    keep = [k for k in range(len(names)) if k not in set(red.fixed)]
    cond = float(np.linalg.cond(scaled_jacobian(jac[:, keep])[0])) if keep else float("inf")
    identifiable = tuple(names[k] for k in keep)
    report = replace(report, identifiable=identifiable, unidentifiable=why, condition_number=cond)
    return report, tuple(redundant)
