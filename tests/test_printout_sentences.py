"""What diagnose and identify print comes from the numbers beside it: fed other numbers, the
sentence moves with them."""

from __future__ import annotations

from pathlib import Path
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


def test_weakly_identified_means_wide_and_not_determined_by_its_value():
    """Above half the physical range and within DETERMINED_Z standard errors of zero: weak;
    a 6-sigma estimate is determined whatever the range; below half the range never weak."""
    from calib.fit.prior import DETERMINED_Z, physical_ranges, weakly_identified
    from twin.formats.parameter_file import load_parameter_set
    from twin.mechanism import Mechanism

    root = Path(__file__).resolve().parent.parent / "models"
    params = load_parameter_set(
        root / "arm6r.params.toml", Mechanism.from_xml(root / "arm6r.xml").model
    )
    half = 0.5 * physical_ranges(params)
    std = 2.0 * half  # every one wide
    std[1] = 0.5 * half[1]  # ... but this one
    z = np.full(len(params), 1.0)
    z[0], z[2], z[3] = 6.0, DETERMINED_Z, 0.999 * DETERMINED_Z
    weak = {w["name"] for w in weakly_identified(params.names, std, params, None, z * std)}
    names = params.names
    assert names[0] not in weak and names[2] not in weak  # 6 and exactly Z sigma: determined
    assert names[1] not in weak  # narrow
    assert names[3] in weak and names[4] in weak
    # without values: the range alone, as before
    plain = {w["name"] for w in weakly_identified(params.names, std, params)}
    assert plain == set(names) - {names[1]}
