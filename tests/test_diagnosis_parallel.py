"""The diagnosis's candidates in worker processes: the same evaluations, bit for bit, as in one
process (each candidate is computed whole by one worker, the results taken in the
candidates' order), on a synthetic problem with two effects in its residual so that the
forward selection also evaluates combinations; the worker count and the progress line."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest
from diagnosis_support import synthetic_context

from calib.cli.commands import main
from calib.correction.kernel_ridge import cross_validate
from calib.diagnosis import problem as problem_module
from calib.diagnosis.candidates import library
from calib.diagnosis.context import Context
from calib.diagnosis.problem import SCHEMES, Problem, fold_labels
from calib.diagnosis.select import select_effects
from calib.diagnosis.unexplained import kernel_heldout
from calib.fit import EXIT_WORKER_LOST
from common import worker_processes as parallel
from tests.real_like_cases import arm_case

N, T, A, P = 120, 3, 6, 12


def _problem() -> tuple[Problem, Context, list]:
    rng = np.random.default_rng(7)
    ctx = synthetic_context(rng, N, A, T)
    cands = library(ctx, masses_defaulted=True)
    by = {c.name: c for c in cands}
    geo = rng.normal(size=(N, 3 * T, P))
    # a gain error and a screw lead of 7 mm pitch, well above the noise
    r = by["gain_error"].design(ctx) @ rng.normal(0, 1e-2, A)
    r = r + by["lead_error"].design(ctx, 7e-3) @ rng.normal(0, 1e-2, 6)
    r = r + rng.normal(0, 1e-5, r.shape)
    return Problem(r, geo), ctx, cands


def _select(workers: str, monkeypatch):
    monkeypatch.setenv(parallel.ENV_WORKERS, workers)
    prob, ctx, cands = _problem()
    folds = {s: fold_labels(ctx.time, 5, s) for s in SCHEMES}
    return select_effects(prob, ctx, folds, cands, prob.r.size, 0.01, 0.05, 2, lambda e, c: None)


def _same(a, b) -> None:
    assert a.names == b.names
    np.testing.assert_array_equal(a.shapes, b.shapes)  # NaN: no shape, equal to NaN here
    for s in SCHEMES:
        np.testing.assert_array_equal(a.fold_shapes[s], b.fold_shapes[s])
    for s in SCHEMES:
        np.testing.assert_array_equal(a.heldout[s], b.heldout[s])
    np.testing.assert_array_equal(a.fit.theta, b.fit.theta)
    np.testing.assert_array_equal(a.fit.beta, b.fit.beta)


def test_candidates_in_two_processes_are_those_of_one(monkeypatch):
    one = _select("1", monkeypatch)
    two = _select("2", monkeypatch)
    assert {c.name for c in one.chosen} == {"gain_error", "lead_error"}
    assert [c.name for c in two.chosen] == [c.name for c in one.chosen]
    assert one.refused == two.refused and one.why_not == two.why_not
    assert one.singles.keys() == two.singles.keys()
    for k in one.singles:
        _same(one.singles[k], two.singles[k])
    _same(one.current, two.current)  # a combination, evaluated by a worker in ``two``


def test_map_in_order_runs_in_workers_and_keeps_the_order():
    here = os.getpid()
    got = list(parallel.map_in_order(lambda i: (i * i, os.getpid()), 7, 2))
    assert [v for v, _ in got] == [i * i for i in range(7)]
    assert all(pid != here for _, pid in got)
    assert list(parallel.map_in_order(lambda i: os.getpid(), 3, 1)) == [here] * 3


def test_worker_count(monkeypatch):
    monkeypatch.delenv(parallel.ENV_WORKERS, raising=False)
    assert parallel.worker_count(parallel.PARALLEL_MIN_ROWS - 1, 12) == 1  # a short run
    cores = os.cpu_count() or 1
    assert parallel.worker_count(parallel.PARALLEL_MIN_ROWS, 12) == min(cores, 12)
    monkeypatch.setenv(parallel.ENV_WORKERS, "3")
    assert parallel.worker_count(10, 12) == 3 and parallel.worker_count(10, 2) == 2
    monkeypatch.setenv(parallel.ENV_WORKERS, "two")
    with pytest.raises(ValueError, match="PKM_DIAGNOSIS_WORKERS='two' is not a whole number"):
        parallel.worker_count(10, 12)


def test_progress_line_only_on_a_long_run(monkeypatch, capsys):
    p = parallel.Progress("candidates", 4, 2)
    p.step("gain_error")
    assert capsys.readouterr().err == ""  # within PROGRESS_AFTER_S
    monkeypatch.setattr(parallel, "PROGRESS_AFTER_S", 0.0)
    p.step("backlash")
    err = capsys.readouterr().err
    assert err.startswith("diagnosis: 2 of 4 candidates evaluated (backlash) after ")
    assert err.rstrip().endswith(" s on 2 processes")


def test_kernel_corrections_in_two_processes_are_those_of_one(monkeypatch):
    """Every (group, scheme, fold) kernel correction of the 'nothing physical' stage, and the
    residual correction's cross-validation folds: the same numbers in two processes."""
    prob, ctx, _ = _problem()
    folds = {s: fold_labels(ctx.time, 5, s) for s in SCHEMES}
    keep = np.ones(prob.r.shape)
    groups = {  # features(ctx) without the orientation (the synthetic poses have none)
        "tool position": ctx.targets.mean(axis=1),
        "actuator commands": ctx.commands,
        "measurement order": ctx.time[:, None],
    }
    x = groups["tool position"]
    labels = fold_labels(ctx.time, 5, "blocked")
    got = {}
    for workers in ("1", "2"):
        monkeypatch.setenv(parallel.ENV_WORKERS, workers)
        got[workers] = (
            kernel_heldout(prob, groups, folds, keep),
            cross_validate(x, prob.r, labels),
        )
    (held_1, cv_1), (held_2, cv_2) = got["1"], got["2"]
    assert held_1.keys() == groups.keys() == held_2.keys()
    for g in groups:
        for s in SCHEMES:
            assert held_1[g][s].shape == (N,) and np.all(held_1[g][s] > 0)
            np.testing.assert_array_equal(held_1[g][s], held_2[g][s])
    np.testing.assert_array_equal(cv_1.sse, cv_2.sse)
    np.testing.assert_array_equal(cv_1.after, cv_2.after)
    np.testing.assert_array_equal(cv_1.distance, cv_2.distance)
    assert (cv_1.length_scale, cv_1.ratio) == (cv_2.length_scale, cv_2.ratio)
    assert np.all(cv_1.distance > 0)  # every pose away from its fold's training poses


def _same_bases(here: Problem, there: Problem, sets: list[np.ndarray]) -> None:
    for poses in sets:
        for a, b in (
            (here.basis(poses), there.basis(poses)),
            (here.pinv(poses), there.pinv(poses)),
            *zip(here.projected_residual(poses), there.projected_residual(poses), strict=True),
        ):
            np.testing.assert_array_equal(a, b)
            assert a.strides == b.strides


@pytest.mark.parametrize("budget", [1 << 30, 200_000, 0])
def test_bases_made_in_two_processes_are_those_of_one(monkeypatch, budget):
    """Problem.fill in two workers (into shared memory) gives the bases, pseudo-inverses and
    projected residuals that Problem.basis makes here: the same numbers and the same memory
    layout (a BLAS product's order of sums follows the layout, so a row-major copy of numpy's
    column-major Q changed a held-out RMS in its last bit), whether the pseudo-inverses are
    kept (all, the first two sets', none) or made again when asked."""
    monkeypatch.setattr(problem_module, "PINV_BUDGET", budget)
    prob, ctx, _ = _problem()
    sets = [fold_labels(ctx.time, 5, s) != f for s in SCHEMES for f in range(5)]
    sets.append(sets[0])  # asked twice: made once
    deficient = prob.geo.copy()
    deficient[:, :, 3] = deficient[:, :, 2]  # two equal columns: Q is a part of U
    for geo in (prob.geo, deficient):
        here, there = Problem(prob.r, geo), Problem(prob.r, geo)
        there.fill(sets, 2)
        assert len(there._cache) == 2 * 10
        rows_each = 96 * 3 * T * P * 8  # 4 of 5 folds' poses
        assert there._pinv_bytes == min(budget // rows_each, 10) * rows_each
        assert there._pinv_bytes // rows_each == {1 << 30: 10, 200_000: 2, 0: 0}[budget]
        kept = [there._cache[s.tobytes()].kept_pinv is not None for s in sets[:10]]
        assert kept == [i < there._pinv_bytes // rows_each for i in range(10)]
        _same_bases(here, there, sets)
        rt, rp = there.projected_residual(sets[0])
        q = there.basis(sets[0])
        assert q.shape[1] == (P if geo is prob.geo else P - 1)
        np.testing.assert_allclose(q.T @ rp, 0.0, atol=1e-12 * np.linalg.norm(rt))


def test_a_pseudo_inverse_made_again_is_the_kept_one(monkeypatch):
    """Beyond the budget G+ is made from the SVD's factors each time a fit asks: the numbers
    of the kept one, a rank-deficient geometry included (Q then a part of U)."""
    prob, ctx, _ = _problem()
    geo = prob.geo.copy()
    geo[:, :, 3] = geo[:, :, 2]  # two equal columns: rank P - 1
    sets = [fold_labels(ctx.time, 5, "random") != f for f in range(5)]
    kept = Problem(prob.r, geo)
    kept.fill(sets, 1)
    monkeypatch.setattr(problem_module, "PINV_BUDGET", 0)
    made = Problem(prob.r, geo)
    _same_bases(kept, made, sets)
    assert made.basis(sets[0]).shape[1] == P - 1
    assert all(made._cache[s.tobytes()].kept_pinv is None for s in sets)
    assert all(kept._cache[s.tobytes()].kept_pinv is not None for s in sets)


def _killed_at(i: int):
    def task(j: int) -> int:
        if j == i:
            os.kill(os.getpid(), signal.SIGKILL)  # as the out-of-memory killer does
        return j

    return task


def test_a_killed_worker_stops_the_map_with_the_cause():
    """A worker the system kills (the out-of-memory killer on a large campaign) must not
    leave the parent waiting for its result forever: WorkerLost, saying what happened and
    what to do; the next map runs as usual."""
    with pytest.raises(
        parallel.WorkerLost,
        match=r"lack of memory; the memory a campaign needs is in the guide",
    ):
        list(parallel.map_in_order(_killed_at(3), 6, 2))
    assert list(parallel.map_in_order(lambda i: i + 1, 4, 2)) == [1, 2, 3, 4]


def test_a_task_runs_its_own_maps_in_its_worker(monkeypatch):
    """No workers of workers: inside a worker, worker_count is 1 and a map runs in place."""
    monkeypatch.setenv(parallel.ENV_WORKERS, "2")

    def task(i: int) -> tuple[int, int, list[int]]:
        inner = parallel.worker_count(10**6, 4)
        return i, inner, list(parallel.map_in_order(lambda j: os.getpid(), 2, inner))

    got = list(parallel.map_in_order(task, 3, 2))
    assert [i for i, _, _ in got] == [0, 1, 2]
    assert all(inner == 1 for _, inner, _ in got)
    assert all(len(set(pids)) == 1 and pids[0] != os.getpid() for _, _, pids in got)


_REAL_RUN = parallel._run


def _run_killing_the_second_candidate(i: int):
    """common.worker_processes._run, but the worker of the second candidate is killed."""
    task = parallel._TASK
    if task is not None and task.__qualname__.startswith("select_effects.") and i == 1:
        os.kill(os.getpid(), signal.SIGKILL)
    return _REAL_RUN(i)


def test_diagnose_whose_worker_is_killed_exits_6_and_writes_nothing(tmp_path, monkeypatch, capsys):
    case = arm_case(tmp_path)
    monkeypatch.setenv(parallel.ENV_WORKERS, "2")
    monkeypatch.setattr(parallel, "_run", _run_killing_the_second_candidate)
    out = tmp_path / "d.json"
    files = ["--model", str(case.model), "--errors", str(case.errors), "--data", str(case.data)]
    code = main(["diagnose", *files, "--set", "calibration", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == EXIT_WORKER_LOST == 6
    assert "error: a worker process ended abruptly" in err and "lack of memory" in err
    assert err.rstrip().endswith("'What a campaign costs'): nothing written")
    assert not out.exists() and not list(tmp_path.glob("d.*"))
