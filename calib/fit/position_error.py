"""The project's one accuracy metric: the 3D position error of each reading.

A reading is one target at one pose; its error is |p_measured - p_model| (a distance, not a
coordinate). RMS, mean and max are taken over readings. A per-coordinate RMS is sqrt(3)
smaller for isotropic noise and is only ever printed under that name.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class PositionErrorStats:
    """RMS, mean and max of the 3D position error per reading, millimetres."""

    n: int
    rms_mm: float
    mean_mm: float
    max_mm: float

    def as_dict(self) -> dict[str, float | int]:
        return {"n": self.n, "rms_mm": self.rms_mm, "mean_mm": self.mean_mm, "max_mm": self.max_mm}

    def describe(self) -> str:
        return f"RMS {self.rms_mm:.4f} mm, mean {self.mean_mm:.4f} mm, max {self.max_mm:.4f} mm"


def error_norms(measured: ArrayLike, predicted: ArrayLike) -> np.ndarray:
    """|measured - predicted| over the last axis (metres in, metres out)."""
    d = np.asarray(measured, dtype=float) - np.asarray(predicted, dtype=float)
    return np.linalg.norm(d, axis=-1)


def stats_mm(norms_m: ArrayLike) -> PositionErrorStats:
    """Statistics of 3D error norms given in metres, reported in millimetres."""
    e = np.asarray(norms_m, dtype=float).reshape(-1) * 1e3
    if e.size == 0:
        return PositionErrorStats(0, float("nan"), float("nan"), float("nan"))
    return PositionErrorStats(
        n=int(e.size),
        rms_mm=float(np.sqrt(np.mean(e * e))),
        mean_mm=float(np.mean(e)),
        max_mm=float(np.max(e)),
    )
