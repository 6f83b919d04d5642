"""The shape scan's fast path (every grid shape's columns computed once and reused by every
training set) against the reference path (the columns of each shape formed anew), on a
synthetic problem: the same training RSS at every grid shape to 1e-12."""

from __future__ import annotations

import numpy as np
import pytest

from calib.diagnosis_candidates import library
from calib.diagnosis_context import Context
from calib.diagnosis_fit import (
    RCOND,
    Problem,
    _explained,
    _normal_equations_offsets,
    _orth,
    fold_labels,
    grid_offsets,
    orth_and_pinv,
    projection,
    rss_over_grid,
)

N, T, A, P = 60, 3, 6, 12


@pytest.fixture(scope="module")
def setup():
    rng = np.random.default_rng(3)
    slide = np.array([True, True, True, False, False, False])
    commands = np.where(slide, rng.uniform(0.6, 1.1, (N, A)), rng.uniform(-1.0, 1.0, (N, A)))
    rows = np.ones((N, 3 * T), bool)
    rows[5, :3] = False  # a rejected reading
    ctx = Context(
        commands=commands,
        time=np.arange(N, dtype=float),
        previous=commands[0] - 0.01,
        is_slide=slide,
        actuator_names=tuple(f"a{i}" for i in range(A)),
        time_unit="pose",
        j_act=rng.normal(size=(N, 3 * T, A)),
        targets=rng.normal(size=(N, T, 3)),
        head=np.array([1.5, 0.0, 0.3]),
        rows=rows,
    )
    prob = Problem(rng.normal(size=(N, 3 * T)) * rows, rng.normal(size=(N, 3 * T, P)))
    return ctx, prob


@pytest.mark.parametrize("scheme", ["blocked", "random"])
def test_cached_scan_matches_the_reference(setup, scheme):
    ctx, prob = setup
    cands = library(ctx, masses_defaulted=True)
    shaped = [c for c in cands if c.shaped]
    assert {c.name for c in shaped} >= {"lead_error", "zero_drift", "thermal_growth"}
    labels = fold_labels(ctx.time, 5, scheme)
    backlash = next(c for c in cands if c.name == "backlash").design(ctx)
    for cand in shaped:
        grid = np.asarray(cand.grid(ctx), dtype=float)
        some = np.unique(np.linspace(0, len(grid) - 1, 40).astype(int))  # the reference is slow
        for f in (0, 3):
            train = labels != f
            for fixed in ([], [backlash]):
                proj = projection(prob, fixed, train)
                fast = rss_over_grid(prob, fixed, cand, ctx, grid, train, cache=True, proj=proj)
                ref = rss_over_grid(prob, fixed, cand, ctx, grid[some], train, proj=proj)
                np.testing.assert_allclose(fast[some], ref, rtol=0, atol=1e-12 * proj.base)


def test_designs_of_a_grid_are_the_designs_of_each_shape(setup):
    ctx, _ = setup
    for cand in library(ctx, masses_defaulted=True):
        grid = np.asarray(cand.grid(ctx), dtype=float)[:50] if cand.shaped else [np.nan]
        many = cand.designs(ctx, grid)
        each = np.stack([cand.design(ctx, float(s)) for s in grid], axis=1)
        np.testing.assert_allclose(many, each, rtol=1e-14, atol=1e-15 * np.max(np.abs(each)))


def test_orth_and_pinv_from_one_svd_are_numpys(setup):
    _, prob = setup
    rng = np.random.default_rng(5)
    deficient = prob.geo[:40].reshape(-1, P) @ np.diag([1.0] * (P - 1) + [0.0])
    for a in (prob.geo[:40].reshape(-1, P), deficient, rng.normal(size=(30, 4)) * 1e-3):
        q, gplus = orth_and_pinv(a)
        np.testing.assert_array_equal(q, _orth(a))
        np.testing.assert_array_equal(gplus, np.linalg.pinv(a, rcond=RCOND))


def test_factored_scan_of_actuator_offsets_matches_the_reference(setup):
    """The scan through the offsets (used on large grids) on every actuator-level candidate."""
    ctx, prob = setup
    labels = fold_labels(ctx.time, 5, "random")
    backlash = next(c for c in library(ctx, True) if c.name == "backlash").design(ctx)
    for cand in library(ctx, masses_defaulted=True):
        if not cand.shaped or cand.offsets is None:
            continue
        grid = np.asarray(cand.grid(ctx), dtype=float)
        some = np.unique(np.linspace(0, len(grid) - 1, 40).astype(int))
        for f in (1, 4):
            train = labels != f
            for fixed in ([], [backlash]):
                proj = projection(prob, fixed, train)
                ata, atb = _normal_equations_offsets(
                    grid_offsets(prob, cand, ctx, grid), proj, train
                )
                fast = proj.base - _explained(ata[some], atb[some])
                ref = rss_over_grid(prob, fixed, cand, ctx, grid[some], train, proj=proj)
                np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-12 * proj.base)
