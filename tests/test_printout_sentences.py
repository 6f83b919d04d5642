"""What diagnose and identify print comes from the numbers beside it: fed other numbers, the
sentence moves with them."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from calib.diagnosis.fit import undetermined
from calib.diagnosis.problem import Problem


class _Columns:
    """A candidate whose design is given columns (N, R, k) at any shape."""

    def __init__(self, x: np.ndarray) -> None:
        self.x = x

    def design(self, ctx, shape) -> np.ndarray:
        return self.x


def test_an_effect_parameter_the_geometry_absorbs_is_undetermined():
    """A column that is a combination of the geometry's, or of another effect parameter's,
    has no value; a column outside their span has one, however small its effect."""
    rng = np.random.default_rng(0)
    n, rows, p = 40, 6, 4
    geo = rng.normal(size=(n, rows, p))
    own = rng.normal(size=(n, rows))
    x = np.stack(
        [
            geo[:, :, 0] - 2.5 * geo[:, :, 3],  # the geometry's
            own,
            -3.0 * own,  # the previous one's: both undetermined
            1e-6 * rng.normal(size=(n, rows)),  # small but its own
            np.zeros((n, rows)),  # not seen: no column, counted elsewhere
        ],
        axis=2,
    )
    prob = Problem(rng.normal(size=(n, rows)), geo)
    ctx, ev = SimpleNamespace(n_poses=n), SimpleNamespace(shapes=(float("nan"),))
    got = undetermined(prob, ctx, [_Columns(x)], ev)
    assert got.tolist() == [True, True, True, False, False]
    # the same columns without the geometric combination: each determined
    x2 = x.copy()
    x2[:, :, 0] = rng.normal(size=(n, rows))
    x2[:, :, 2] = rng.normal(size=(n, rows))
    got = undetermined(prob, ctx, [_Columns(x2)], ev)
    assert got.tolist() == [False] * 5
