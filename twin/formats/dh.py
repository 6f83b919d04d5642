"""A DH table as data: its joints, tool, reflectors and base, in SI (read by twin.formats.dh_table,
turned into an MJCF by twin.formats.dh_mjcf, read back from a model by twin.formats.dh_extract)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from twin.formats.parameter_file import closest


class DHTableError(ValueError):
    """A DH table that cannot be read; the message names file, line and column."""


@dataclass(frozen=True)
class DHJoint:
    """One row, SI: alpha, theta in rad; a, d in m; limits and home in rad (R) or m (P)."""

    name: str
    type: str
    alpha: float
    a: float
    d: float
    theta: float
    lower: float
    upper: float
    home: float


@dataclass(frozen=True)
class DHSite:
    """A point (and orientation, rotations about fixed x, y, z) in its frame, SI."""

    name: str
    pos: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class DHTable:
    convention: str
    joints: tuple[DHJoint, ...]
    tool: DHSite
    targets: tuple[DHSite, ...]
    base: DHSite = DHSite("base", (0.0, 0.0, 0.0))
    source: str = "<table>"

    def with_targets(self, names: list[str] | tuple[str, ...]) -> DHTable:
        """The same arm with only the reflectors ``names``, in that order."""
        known = {t.name: t for t in self.targets}
        for n in names:
            if n not in known:
                raise DHTableError(
                    f"{self.source}: no reflector '{n}'{closest(n, known)}; "
                    f"the table has {list(known)}"
                )
        if not names or len(set(names)) != len(names):
            raise DHTableError(f"{self.source}: choose distinct reflectors, got {list(names)}")
        return dataclasses.replace(self, targets=tuple(known[n] for n in names))
