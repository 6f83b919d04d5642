"""Bounded scalar minimisation, several searches side by side.

``scipy.optimize.minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": t})``
(Brent's method: golden sections and parabolic steps inside [a, b]) written step for step as a
generator that yields the point to evaluate and receives its value. Several searches can then
ask for their values together, one evaluation of all their points at once, and each still makes
the same steps with the same arithmetic as scipy's (tests/test_bounded_search.py compares every
point and the minimiser, bit for bit).

The steps are those of scipy.optimize._optimize._minimize_scalar_bounded (scipy 1.17.1),
kept line for line so that the arithmetic stays the same: SciPy is distributed under the
BSD 3-Clause licence, Copyright (c) 2001-2002 Enthought, Inc. 2003, SciPy Developers; its
licence text ships with the installed scipy (scipy-*.dist-info/LICENSE.txt). After a scipy
upgrade, the bit-for-bit test says whether this copy still follows it.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Sequence
from math import sqrt

import numpy as np

MAXITER = 500  # scipy's default number of function evaluations


def bounded_search(
    x1: float, x2: float, xatol: float, maxiter: int = MAXITER
) -> Generator[float, float, float]:
    """Yield the points to evaluate, receive f at each; return the minimiser (scipy's
    ``res.x`` of the bounded method, before its cast to a numpy scalar)."""
    if not (np.isfinite(x1) and np.isfinite(x2)):
        raise ValueError("Optimization bounds must be finite scalars.")
    if x1 > x2:
        raise ValueError("The lower bound exceeds the upper bound.")
    maxfun = maxiter
    sqrt_eps = sqrt(2.2e-16)
    golden_mean = 0.5 * (3.0 - sqrt(5.0))
    a, b = x1, x2
    fulc = a + golden_mean * (b - a)
    nfc, xf = fulc, fulc
    rat = e = 0.0
    x = xf
    fx = yield x
    num = 1

    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = sqrt_eps * np.abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1

    while np.abs(xf - xm) > (tol2 - 0.5 * (b - a)):
        golden = 1
        # Check for parabolic fit
        if np.abs(e) > tol1:
            golden = 0
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = np.abs(q)
            r = e
            e = rat

            # Check for acceptability of parabola
            if (np.abs(p) < np.abs(0.5 * q * r)) and (p > q * (a - xf)) and (p < q * (b - xf)):
                rat = (p + 0.0) / q
                x = xf + rat

                if ((x - a) < tol2) or ((b - x) < tol2):
                    si = np.sign(xm - xf) + ((xm - xf) == 0)
                    rat = tol1 * si
            else:  # do a golden-section step
                golden = 1

        if golden:  # do a golden-section step
            if xf >= xm:
                e = a - xf
            else:
                e = b - xf
            rat = golden_mean * e

        si = np.sign(rat) + (rat == 0)
        x = xf + si * np.maximum(np.abs(rat), tol1)
        fu = yield x
        num += 1

        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if (fu <= fnfc) or (nfc == xf):
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif (fu <= ffulc) or (fulc == xf) or (fulc == nfc):
                fulc, ffulc = x, fu

        xm = 0.5 * (a + b)
        tol1 = sqrt_eps * np.abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1

        if num >= maxfun:
            break
    return xf


def minimise_together(
    fun_many: Callable[[list[float]], Sequence[float]],
    bounds: Sequence[tuple[float, float]],
    xatols: Sequence[float],
) -> list[float]:
    """The minimiser of f in each of ``bounds`` (with its ``xatols``), every search stepping
    as :func:`bounded_search`; ``fun_many(points)`` returns f at several points at once (the
    points of the searches still running, in the order of ``bounds``)."""
    searches = [bounded_search(lo, hi, t) for (lo, hi), t in zip(bounds, xatols, strict=True)]
    out: list[float] = [float("nan")] * len(searches)
    asks = {i: next(s) for i, s in enumerate(searches)}
    while asks:
        values = fun_many(list(asks.values()))
        nxt = {}
        for (i, _), f in zip(asks.items(), values, strict=True):
            try:
                nxt[i] = searches[i].send(f)
            except StopIteration as done:
                out[i] = done.value
        asks = nxt
    return out
