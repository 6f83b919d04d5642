"""What a candidate of the diagnosis is: a family of identification columns X(shape) (N poses,
R residual rows, k linear parameters), linear in its parameters once its shape (a pitch, a time
constant, a harmonic, a payload) is fixed; actuator-level ones as offsets on the actuators.
The library of candidates is calib.diagnosis.candidates."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from calib.diagnosis.context import Context

Offsets = Callable[[Context, float], np.ndarray]  # (N, A, k) actuator offsets per parameter
ManyOffsets = Callable[[Context, np.ndarray], np.ndarray]  # (N, S, A, k) at S shapes at once
# the offsets at S shapes as their (actuator, parameter) pairs: o (N, S, P), act (P,),
# col (P,) and k, the values of ManyOffsets at [:, :, act, col] (zero elsewhere)
PairOffsets = Callable[[Context, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray, int]]
Columns = Callable[[Context, float], np.ndarray]  # (N, R, k) identification columns
Grid = Callable[[Context], np.ndarray]

NO_SHAPE = float("nan")


@dataclass(frozen=True)
class PoseRows:
    """Some poses of a context (``poses`` a mask, None: all) with their actuator Jacobians
    and kept-row weights (R, 1), what a design at those poses reads whatever the shape."""

    poses: np.ndarray | None
    j_act: np.ndarray | None
    rows: np.ndarray | None

    @classmethod
    def of(cls, ctx: Context, poses: np.ndarray | None = None) -> PoseRows:
        j, rows = ctx.j_act, ctx.rows
        if poses is not None:
            j = None if j is None else j[poses]
            rows = None if rows is None else rows[poses]
        return cls(poses, j, None if rows is None else rows[:, :, None])


@dataclass(frozen=True)
class Candidate:
    """One family of effects. ``offsets`` (actuator-level) or ``columns`` (direct)."""

    name: str
    parameters: tuple[str, ...]
    units: tuple[str, ...]  # display unit of each linear parameter
    factors: tuple[float, ...]  # SI value x factor = display value
    offsets: Offsets | None = None
    offsets_many: ManyOffsets | None = None  # the offsets at many shapes in one computation
    offset_pairs: PairOffsets | None = None  # ... as the pairs that can be nonzero, no zeros
    # each parameter offsets one actuator (diagonal offsets): every value of J_act D is then a
    # single product, whatever the order of the sum, and a batched matrix product forms it
    one_actuator: bool = False
    columns: Columns | None = None
    grid: Grid | None = None  # shape values to scan (None: no shape)
    shape_name: str = ""
    shape_unit: str = ""
    shape_factor: float = 1.0
    shape_log: bool = False  # refine the shape on a log scale
    nonnegative: tuple[bool, ...] = ()  # per parameter: physics forbids a negative value
    physics: str = ""  # what a negative value would mean, for the refusal
    explains: str = ""  # the variable the residual is plotted against
    notes: tuple[str, ...] = field(default=())

    @property
    def shaped(self) -> bool:
        return self.grid is not None

    def design(
        self, ctx: Context, shape: float = NO_SHAPE, poses: np.ndarray | None = None
    ) -> np.ndarray:
        """Identification columns (N, R, k) at these poses for this shape; ``poses`` (a mask):
        only those poses, the values of ``design(ctx, shape)[poses]``."""
        return self.design_at(ctx, shape, PoseRows.of(ctx, poses))

    def design_at(self, ctx: Context, shape: float, at: PoseRows) -> np.ndarray:
        """:meth:`design` at the poses of ``at`` (taken once for the shapes of a search)."""
        if self.columns is not None:
            x = self.columns(ctx, shape)
            x = x if at.poses is None else x[at.poses]
        elif self.one_actuator:  # one product per value: the poses' rows alone
            assert self.offsets is not None and at.j_act is not None
            o = self.offsets(ctx, shape)
            x = np.matmul(at.j_act, o if at.poses is None else o[at.poses])
        else:  # einsum's sums depend on the layout of the operands: all poses, then these
            assert self.offsets is not None and ctx.j_act is not None
            x = np.einsum("nra,nak->nrk", ctx.j_act, self.offsets(ctx, shape))
            x = x if at.poses is None else x[at.poses]
        return x if at.rows is None else x * at.rows

    def designs(self, ctx: Context, shapes) -> np.ndarray:
        """Identification columns (N, S, R, k) at these poses for each of ``shapes``: the
        values of :meth:`design` (the actuator offsets of all shapes through J_act at once)."""
        if self.columns is not None:
            x = np.stack([self.columns(ctx, float(s)) for s in shapes], axis=1)
        else:
            assert ctx.j_act is not None
            x = np.matmul(ctx.j_act[:, None], self.offsets_at(ctx, shapes))
        return x if ctx.rows is None else x * ctx.rows[:, None, :, None]

    def offsets_at(self, ctx: Context, shapes) -> np.ndarray:
        """Actuator offsets (N, S, A, k) at each of ``shapes``: the values of :attr:`offsets`
        shape by shape (from :attr:`offsets_many` at once when the candidate has it)."""
        assert self.offsets is not None
        if self.offsets_many is not None:
            return self.offsets_many(ctx, np.asarray(shapes, dtype=float))
        return np.stack([self.offsets(ctx, float(s)) for s in shapes], axis=1)

    @property
    def regressor(self) -> Offsets | None:  # the former name of the offsets function
        return self.offsets
