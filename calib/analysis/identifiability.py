"""Which parameters a pose set can identify, and why the others cannot.

Everything is computed on the column-scaled identification Jacobian (each column divided by
its Euclidean norm), so that millimetres and radians do not mix and the numbers do not depend
on the units. Rank and condition number come from the SVD; *which* parameters form an
identifiable set comes from a pivoted QR whose pivot choice is deterministic on every
platform: the column with the largest remaining norm wins, and norms within a relative
``TIE`` of each other count as equal, the earlier parameter (declared order) winning.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

RANK_RTOL = 1e-9  # a scaled singular value below this fraction of the largest is zero
TIE = 1e-9  # relative difference under which two pivot candidates count as equal


@dataclass(frozen=True)
class IdentifiabilityReport:
    names: tuple[str, ...]
    n_rows: int
    rank: int
    singular_values: np.ndarray  # of the column-scaled Jacobian, descending
    condition_number: float  # of the identifiable columns (scaled)
    identifiable: tuple[str, ...]
    unidentifiable: dict[str, str] = field(default_factory=dict)  # name -> reason

    @property
    def n_parameters(self) -> int:
        return len(self.names)

    @property
    def n_identifiable(self) -> int:
        return len(self.identifiable)

    def summary(self) -> str:
        lines = [
            f"{self.n_identifiable} of {self.n_parameters} parameters identifiable "
            f"(rank {self.rank}, {self.n_rows} equations, scaled condition number "
            f"{self.condition_number:.4g})"
        ]
        lines += [f"  {n}: {why}" for n, why in self.unidentifiable.items()]
        return "\n".join(lines)


ZERO_RTOL = 1e-10  # a column whose norm is below this fraction of the largest has no effect


def column_scale(jac: np.ndarray) -> np.ndarray:
    """Euclidean norm of each column (1 for a zero column, which is reported separately)."""
    norms = np.linalg.norm(jac, axis=0)
    return np.where(norms > 0, norms, 1.0)


def zero_columns(jac: np.ndarray) -> np.ndarray:
    """Columns that are zero up to round-off (no effect on the measurements)."""
    norms = np.linalg.norm(jac, axis=0)
    top = norms.max() if norms.size else 0.0
    return norms <= ZERO_RTOL * top if top > 0 else np.ones(norms.shape, dtype=bool)


def scaled_jacobian(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Column-scaled copy (unit columns), the scale, and the zero-column mask.

    Columns that are zero up to round-off are set to exactly zero rather than scaled up:
    scaling them would turn round-off into unit columns of noise.
    """
    jac = np.asarray(jac, dtype=float)
    zero = zero_columns(jac)
    scale = column_scale(jac)
    scaled = jac / scale
    scaled[:, zero] = 0.0
    return scaled, scale, zero


def pivoted_qr_order(a: np.ndarray, rank: int) -> list[int]:
    """Column order of a Householder QR with deterministic column pivoting (first ``rank``)."""
    r = np.array(a, dtype=float)
    m, n = r.shape
    remaining = list(range(n))
    chosen: list[int] = []
    for k in range(min(rank, m)):
        norms = np.linalg.norm(r[k:, remaining], axis=0)
        top = norms.max()
        best = remaining[int(np.argmax(norms >= top * (1 - TIE)))]  # the first within TIE
        chosen.append(best)
        remaining.remove(best)
        x = r[k:, best].copy()
        v = x.copy()
        v[0] += np.copysign(np.linalg.norm(x), x[0] if x[0] != 0 else 1.0)
        nv = np.linalg.norm(v)
        if nv > 0:
            v /= nv
            r[k:, :] -= 2.0 * np.outer(v, v @ r[k:, :])
        # swap the chosen column's reduced entries into position k is not needed: we only
        # track the order and keep operating on the original column indices
    return chosen


def analyse(jac: np.ndarray, names: tuple[str, ...] | list[str]) -> IdentifiabilityReport:
    """Rank, singular values, condition number and identifiable set of a Jacobian (m, n)."""
    jac = np.asarray(jac, dtype=float)
    names = tuple(names)
    m, n = jac.shape
    if n != len(names):
        raise ValueError(f"Jacobian has {n} columns but {len(names)} names were given")
    scaled, _, zero = scaled_jacobian(jac)
    if m > n:  # the same columns' geometry in n rows: R of scaled = QR, Q orthonormal
        scaled = np.linalg.qr(scaled, mode="r")
    s = np.linalg.svd(scaled, compute_uv=False)
    rank = int(np.sum(s > RANK_RTOL * s[0])) if s.size and s[0] > 0 else 0
    # full column rank: every column is chosen, whatever the pivots' order
    order = list(range(n)) if rank == n else pivoted_qr_order(scaled, rank)
    identifiable_idx = sorted(order)
    reasons: dict[str, str] = {}
    sub = scaled[:, identifiable_idx]
    chosen = set(identifiable_idx)
    # every other effective column on the identifiable ones, in one least-squares solve
    combined = [j for j in range(n) if j not in chosen and not zero[j]]
    coefs = np.linalg.lstsq(sub, scaled[:, combined], rcond=None)[0] if combined else None
    for j in range(n):
        if j in chosen:
            continue
        if zero[j]:
            reasons[names[j]] = "has no effect on the measurements (zero Jacobian column)"
            continue
        assert coefs is not None
        coef = coefs[:, combined.index(j)]
        top = np.argsort(-np.abs(coef))[:3]
        terms = " ".join(
            f"{'+' if coef[t] >= 0 else '-'} {abs(coef[t]):.3g} {names[identifiable_idx[t]]}"
            for t in top
            if abs(coef[t]) > 1e-6
        )
        reasons[names[j]] = (
            f"its effect is a combination of identifiable parameters (scaled: {terms.lstrip('+ ')})"
        )
    if m < n:
        for nm in list(reasons):
            reasons[nm] += f"; {m} equations for {n} parameters"
    if not identifiable_idx:
        cond = float("inf")
    elif len(identifiable_idx) == n:  # sub is scaled: its singular values are s
        cond = float(s[0] / s[-1])
    else:
        cond = float(np.linalg.cond(sub))
    return IdentifiabilityReport(
        names=names,
        n_rows=m,
        rank=rank,
        singular_values=s,
        condition_number=cond,
        identifiable=tuple(names[j] for j in identifiable_idx),
        unidentifiable=reasons,
    )
