"""Numbers as generated model files write them: the same text on every CPU, within tolerance.

numpy hands even 3x3 products to OpenBLAS, whose kernel is chosen per CPU: a value that is
0 in exact arithmetic comes out as +-1e-17..1e-33 on one machine and 0 on another, and a
quaternion of a 180-degree rotation (w about 0) flips sign under a ``w >= 0`` rule. So the
generators snap every |value| below ``SNAP`` to 0 (model files are in metres and radians,
where 1e-12 is far below anything physical) and make the first component of a quaternion
whose magnitude exceeds ``SNAP`` positive. What remains are last-digit differences that can
change the 12th significant digit of a few numbers: generated files are compared with
committed ones numerically (``tests/test_generated_models.py``), never as text.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

SNAP = 1e-12


def snap(values: ArrayLike, tol: float = SNAP) -> NDArray[np.float64]:
    """Copy with every |x| < tol set to +0.0 (negative zero too)."""
    v = np.array(values, dtype=float)
    v[np.abs(v) < tol] = 0.0
    return v + 0.0  # -0.0 -> 0.0


def canonical_quat(q: ArrayLike, tol: float = SNAP) -> NDArray[np.float64]:
    """Unit quaternion (w, x, y, z), snapped, with its first non-zero component positive."""
    v = np.asarray(q, dtype=float)
    v = snap(v / np.linalg.norm(v), tol)
    nonzero = np.flatnonzero(v)
    if nonzero.size and v[nonzero[0]] < 0:
        v = -v
    return v + 0.0


def fmt(values: ArrayLike) -> str:
    """Space-separated, 12 significant digits, tiny values written as 0."""
    return " ".join(f"{float(x):.12g}" for x in np.atleast_1d(snap(values)))
