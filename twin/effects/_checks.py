"""Validation helpers shared by the effects' constructors (ValueError naming the argument)."""

from __future__ import annotations

import math


def finite(value: float, name: str, *, min: float | None = None, above: float | None = None):
    """``value`` as a float; finite and (optionally) >= ``min`` or > ``above``."""
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if min is not None and v < min:
        raise ValueError(f"{name} must be >= {min}, got {v}")
    if above is not None and v <= above:
        raise ValueError(f"{name} must be > {above}, got {v}")
    return v


def floats(values, name: str) -> tuple[float, ...]:
    """A tuple of finite floats."""
    out = tuple(float(v) for v in values)
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must be finite numbers, got {values!r}")
    return out


def seed(value: int, name: str = "seed") -> int:
    if isinstance(value, bool) or int(value) != value or value < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)
