"""The bounded search written as a generator against scipy's minimize_scalar(method="bounded"):
the same points evaluated in the same order and the same minimiser, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from calib.diagnosis.bounded_search import bounded_search, minimise_together


def _functions():
    rng = np.random.default_rng(7)
    noise = rng.normal(size=64)
    return [
        lambda x: (x - 0.3) ** 2,
        lambda x: np.cos(3 * x) + 0.1 * x,
        lambda x: abs(x - 1.234567),
        lambda x: 1.0,  # flat
        lambda x: -x,  # minimum at the bound
        lambda x: np.exp(x) - 2 * x + 1e-9 * noise[int(abs(x) * 1e6) % 64],  # rough
        lambda x: np.floor(x * 5) / 5,  # steps
        lambda x: 1e12 + 1e-3 * (x - 2.5) ** 2,  # a small change on a large value
    ]


def _scipy(f, lo, hi, xatol):
    seen = []

    def g(x):
        seen.append(x)
        return float(f(x))

    res = minimize_scalar(g, bounds=(lo, hi), method="bounded", options={"xatol": xatol})
    return seen, float(res.x)


def _ours(f, lo, hi, xatol):
    seen, search = [], bounded_search(lo, hi, xatol)
    x = next(search)
    try:
        while True:
            seen.append(x)
            x = search.send(float(f(x)))
    except StopIteration as done:
        return seen, float(done.value)


BOUNDS = [(-1.0, 2.0), (0.0, 1e-6), (np.log(2.9), np.log(485.0)), (-3.0, 5.0), (1e-3, 2e-3)]


@pytest.mark.parametrize("lo, hi", BOUNDS)
def test_every_point_and_the_minimiser_are_scipys(lo, hi):
    for f in _functions():
        for xatol in (1e-2 * (hi - lo) + 1e-15, 1e-5, 1e-12):
            ref_seen, ref_x = _scipy(f, lo, hi, xatol)
            seen, x = _ours(f, lo, hi, xatol)
            assert len(seen) == len(ref_seen)
            assert all(a == b for a, b in zip(seen, ref_seen, strict=True))
            assert x == ref_x


def test_searches_side_by_side_are_each_search_alone():
    """One function, several intervals: the searches run together (their points evaluated in
    one call) find what each finds alone, and every call holds the searches still running."""
    bounds = [(-1.0, 2.0), (0.0, 3.0), (0.5, 2.0), (2.0, 2.5)]
    xatols = [1e-2, 1e-4, 1e-3, 1e-2]
    for f in _functions():
        sizes = []

        def many(points, f=f, sizes=sizes):
            sizes.append(len(points))
            return [float(f(x)) for x in points]

        together = minimise_together(many, bounds, xatols)
        alone = [_scipy(f, lo, hi, t)[1] for (lo, hi), t in zip(bounds, xatols, strict=True)]
        assert together == alone
        assert sizes[0] == len(bounds) and sizes == sorted(sizes, reverse=True)
