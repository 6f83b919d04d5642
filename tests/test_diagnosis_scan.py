"""The shape scan's fast path (every grid shape's columns computed once and reused by every
training set) against the reference path (the columns of each shape formed anew), on a
synthetic problem: the same training RSS at every grid shape to 1e-12."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from diagnosis_support import synthetic_context

from calib.diagnosis.basis import RCOND, _orth, column_scale, make_basis
from calib.diagnosis.candidate import PoseRows
from calib.diagnosis.candidates import library
from calib.diagnosis.gravity import GravityLoads
from calib.diagnosis.problem import Problem, fit, fold_labels, heldout_sse
from calib.diagnosis.shape_scan import (
    INNER_FOLDS,
    _explained,
    _inner_cv,
    _normal_equations_offsets,
    grid_offsets,
    projection,
    rss_at,
    rss_over_grid,
)

N, T, A, P = 60, 3, 6, 12


@pytest.fixture(scope="module")
def setup():
    rng = np.random.default_rng(3)
    rows = np.ones((N, 3 * T), bool)
    rows[5, :3] = False  # a rejected reading
    ctx = synthetic_context(rng, N, A, T, rows)
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


def test_basis_and_pinv_from_one_svd_are_numpys(setup):
    _, prob = setup
    rng = np.random.default_rng(5)
    deficient = prob.geo[:40].reshape(-1, P) @ np.diag([1.0] * (P - 1) + [0.0])
    for a in (prob.geo[:40].reshape(-1, P), deficient, rng.normal(size=(30, 4)) * 1e-3):
        scale = column_scale(a)
        b = make_basis(a, keep_pinv=True)
        np.testing.assert_array_equal(b.q, _orth(a / scale))
        np.testing.assert_array_equal(
            b.pinv(), np.linalg.pinv(a / scale, rcond=RCOND) / scale[:, None]
        )


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


def _shaped_grid(cand, ctx):
    return np.asarray(cand.grid(ctx), dtype=float) if cand.shaped else np.array([np.nan])


def test_offsets_of_many_shapes_are_the_offsets_of_each(setup):
    ctx, _ = setup
    for cand in library(ctx, masses_defaulted=True):
        if cand.offsets is None:
            continue
        grid = _shaped_grid(cand, ctx)[:100]
        each = np.stack([cand.offsets(ctx, float(s)) for s in grid], axis=1)
        np.testing.assert_array_equal(cand.offsets_at(ctx, grid), each)


def test_offset_pairs_are_the_nonzero_offsets(setup):
    """A candidate's offsets as (actuator, parameter) pairs hold every nonzero value of its
    dense offsets, bit for bit, and zeros only elsewhere; the grid's offsets from them are
    those from the dense array (one commanded-still actuator: its pairs all zero, dropped)."""
    ctx, prob = setup
    still = dataclasses.replace(ctx, commands=ctx.commands.copy())
    still.commands[:, 1] = 0.0  # sin of a zero phase: a pair the dense path never keeps
    for c in (ctx, still):
        cand = next(k for k in library(c, masses_defaulted=True) if k.name == "lead_error")
        assert cand.offset_pairs is not None
        grid = np.asarray(cand.grid(c), dtype=float)
        dense = cand.offsets_at(c, grid)
        o, act, col, k = cand.offset_pairs(c, grid)
        assert k == dense.shape[3]
        np.testing.assert_array_equal(o, dense[:, :, act, col])
        rest = dense.copy()
        rest[:, :, act, col] = 0.0
        assert not np.any(rest)
        fast = grid_offsets(prob, cand, c, grid)
        slow = grid_offsets(
            Problem(prob.r, prob.geo), dataclasses.replace(cand, offset_pairs=None), c, grid
        )
        for a, b in ((fast.o, slow.o), (fast.act, slow.act), (fast.col, slow.col)):
            np.testing.assert_array_equal(a, b)
        assert fast.k == slow.k


def test_one_actuator_candidates_move_one_actuator_per_parameter(setup):
    """The flag lets the design take J_act D as one matrix product: it must hold at every
    shape, and the product must then be einsum's sum bit for bit."""
    ctx, _ = setup
    rng = np.random.default_rng(11)
    loads = GravityLoads(rng.normal(size=(N, A)), rng.normal(size=(N, A)), 12.0)
    ctx = dataclasses.replace(ctx, gravity=loads)
    flagged = [
        c
        for defaulted in (True, False)
        for c in library(ctx, masses_defaulted=defaulted)
        if c.one_actuator
    ]
    assert {c.name for c in flagged} >= {
        "gain_error",
        "backlash",
        "zero_drift",
        "lead_error",
        "encoder_eccentricity",
        "gravity_compliance",
    }
    for cand in flagged:
        for s in _shaped_grid(cand, ctx)[::7]:
            o = cand.offsets(ctx, float(s))
            assert np.count_nonzero(o, axis=1).max() <= 1, cand.name
            ref = np.einsum("nra,nak->nrk", ctx.j_act, o) * ctx.rows[:, :, None]
            np.testing.assert_array_equal(cand.design(ctx, float(s)), ref)


def test_design_at_some_poses_is_the_design_of_those_poses(setup):
    ctx, _ = setup
    poses = fold_labels(ctx.time, 5, "random") != 2
    for cand in library(ctx, masses_defaulted=True):
        for s in _shaped_grid(cand, ctx)[:3]:
            full = cand.design(ctx, float(s))
            np.testing.assert_array_equal(cand.design(ctx, float(s), poses), full[poses])


def test_refinement_cost_is_the_scan_of_one_shape(setup):
    """rss_at (the refinement's cost) and rss_over_grid at one shape: the same arithmetic, so
    the same number bit for bit (the refined shapes follow every bit of this cost)."""
    ctx, prob = setup
    cands = library(ctx, masses_defaulted=True)
    backlash = next(c for c in cands if c.name == "backlash").design(ctx)
    train = fold_labels(ctx.time, 5, "blocked") != 1
    at = PoseRows.of(ctx, train)
    for cand in (c for c in cands if c.shaped):
        grid = _shaped_grid(cand, ctx)
        for fixed in ([], [backlash]):
            proj = projection(prob, fixed, train)
            for s in grid[:: max(len(grid) // 5, 1)]:
                one = rss_over_grid(prob, fixed, cand, ctx, [float(s)], train, proj=proj)[0]
                assert rss_at(cand, ctx, [float(s)], at, proj) == [float(one)]
            some = [float(s) for s in grid[:: max(len(grid) // 4, 1)]]
            alone = [rss_at(cand, ctx, [s], at, proj)[0] for s in some]
            assert rss_at(cand, ctx, some, at, proj) == alone


def test_inner_cross_validation_is_fit_and_heldout_sse_fold_by_fold(setup):
    ctx, prob = setup
    cands = library(ctx, masses_defaulted=True)
    backlash = next(c for c in cands if c.name == "backlash").design(ctx)
    lead = next(c for c in cands if c.name == "lead_error")
    xs = [lead.design(ctx, s) for s in (4e-3, 7e-3, 11e-3)]
    poses = fold_labels(ctx.time, 5, "random") != 0
    idx = np.flatnonzero(poses)
    labels = fold_labels(ctx.time[idx], INNER_FOLDS, "random", seed=1)
    for fixed in ([], [backlash]):
        ref = []
        for x in xs:
            sse = 0.0
            for f in range(INNER_FOLDS):
                train, test = np.zeros_like(poses), np.zeros_like(poses)
                train[idx[labels != f]] = True
                test[idx[labels == f]] = True
                ft = fit(prob, [*fixed, x], train)
                sse += float(np.sum(heldout_sse(prob, [*fixed, x], ft, test)))
            ref.append(sse)
        assert _inner_cv(prob, fixed, xs, ctx, poses) == ref
