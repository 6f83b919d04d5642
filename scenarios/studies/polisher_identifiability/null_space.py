"""What a plan cannot see, in the parameters' names: which source errors move no target at
all, and which the plan reads only as combinations with others.

The null space of the column-scaled H is described by its orthogonal projector P = N N^T
(N: an orthonormal basis of it), which does not depend on the basis chosen. Two parameters
belong to one group when P couples them (|P_ij| > COUPLED); in each group of k parameters the
block of P is itself a projector, its trace d the number of directions among them that no
reading of the plan changes, and the plan reads k - d combinations of them. A zero column
(a parameter that moves no target at any pose) is a group of one with d = 1; a parameter
identified alone is a group of one with d = 0. The k - d over all groups add up to the rank.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.analysis import RANK_RTOL, scaled_jacobian

# |P_ij| above this couples parameters i and j. On the polisher's fine plan the entries of P
# are either round-off (below 1e-8, set by the smallest kept singular value, 1e-6 of the
# largest) or couplings (above 1e-4): the bound sits in that gap.
COUPLED = 1e-6


@dataclass(frozen=True)
class NullGroup:
    """Parameters the null space couples: ``unseen`` directions among them no reading sees."""

    members: tuple[str, ...]
    unseen: int

    @property
    def read(self) -> int:
        """How many combinations of the members the plan reads."""
        return len(self.members) - self.unseen


@dataclass(frozen=True)
class NullSpace:
    """The parameters of a plan by what it sees of them."""

    rank: int
    no_effect: tuple[str, ...]  # zero columns: move no target at any pose of the plan
    alone: tuple[str, ...]  # identified one by one (coupled to nothing in the null space)
    mixed: tuple[NullGroup, ...]  # read only as combinations, largest group first
    share: np.ndarray  # each parameter's squared length in the null space (P's diagonal)

    def rows(self, names: list[str]) -> dict[str, dict[str, int]]:
        """Per part of the machine (a name's first field, e.g. ``limb1``; a group spanning
        several parts gets a row of its own): parameters identified alone, combinations read,
        directions unseen among the mixed ones, parameters with no effect."""
        order = list(dict.fromkeys(part(n) for n in names))
        out: dict[str, dict[str, int]] = {}

        def row(key: str) -> dict[str, int]:
            return out.setdefault(key, {"alone": 0, "read": 0, "unseen": 0, "no_effect": 0})

        for key in order:
            row(key)
        for n in self.alone:
            row(part(n))["alone"] += 1
        for n in self.no_effect:
            row(part(n))["no_effect"] += 1
        for g in self.mixed:
            r = row(home(g.members))
            r["read"] += g.read
            r["unseen"] += g.unseen
        return out

    def summary(self, names: list[str]) -> dict:
        """The counts, the rows of :meth:`rows` and the mixed groups, for summary.json."""
        return {
            "rank": self.rank,
            "no_effect": len(self.no_effect),
            "alone": len(self.alone),
            "read_in_combinations": sum(g.read for g in self.mixed),
            "unseen_in_combinations": sum(g.unseen for g in self.mixed),
            "by_part": self.rows(names),
            "groups": [
                {"members": list(g.members), "read": g.read, "unseen": g.unseen} for g in self.mixed
            ],
        }


def part(name: str) -> str:
    """The part of the machine a parameter belongs to: its name's first field."""
    return name.split(".", 1)[0]


def home(members: tuple[str, ...]) -> str:
    """The part all ``members`` belong to, or "limb1 + limb2 + ..." when they span several."""
    parts = list(dict.fromkeys(part(n) for n in members))
    return parts[0] if len(parts) == 1 else " + ".join(parts)


def null_space(h: np.ndarray, names: list[str]) -> NullSpace:
    """The null space of the column-scaled ``h`` (rank as calib.analysis counts it) in groups
    of parameters; see the module's docstring."""
    hs, _, zero = scaled_jacobian(h)
    _, s, vt = np.linalg.svd(hs, full_matrices=True)
    rank = int(np.sum(s > RANK_RTOL * s[0]))
    basis = vt[rank:]
    projector = basis.T @ basis
    share = np.sum(basis**2, axis=0) if len(basis) else np.zeros(len(names))
    coupled = np.abs(projector) > COUPLED
    label = np.full(len(names), -1)
    groups: list[list[int]] = []
    for i in range(len(names)):
        if label[i] >= 0:
            continue
        label[i] = len(groups)
        members, stack = [i], [i]
        while stack:
            for j in np.flatnonzero(coupled[stack.pop()]):
                if label[j] < 0:
                    label[j] = len(groups)
                    members.append(int(j))
                    stack.append(int(j))
        groups.append(sorted(members))
    no_effect, alone, mixed = [], [], []
    for g in groups:
        unseen = round(float(np.trace(projector[np.ix_(g, g)])))
        if len(g) == 1 and zero[g[0]]:
            no_effect.append(names[g[0]])
        elif unseen == 0:
            alone += [names[k] for k in g]
        else:
            mixed.append(NullGroup(tuple(names[k] for k in g), unseen))
    mixed.sort(key=lambda g: (-len(g.members), g.members))
    return NullSpace(rank, tuple(no_effect), tuple(alone), tuple(mixed), share)
