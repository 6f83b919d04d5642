"""Independent tasks evaluated side by side in worker processes, and a progress line.

A task is a function of what the parent process holds (for the diagnosis: a candidate's
nested cross-validation, a kernel correction of one fold, a cross-validation fold of the
residual correction, the Jacobians or gravity loads of a chunk of poses); a worker (a fork of
this process: it reads what the parent computed, without copying it) evaluates whole tasks,
one at a time, with the parent's BLAS threads, and the results come back in the tasks' order.
A task's numbers are therefore those of the serial run, whatever the number of workers.

Workers: ``PKM_DIAGNOSIS_WORKERS`` when set (1: in this process), else the machine's cores
for a long run (at least ``PARALLEL_MIN_ROWS`` residual rows), else this process. Without
``fork`` (not Linux/macOS) or inside a worker (no workers of workers) the tasks run here.

A worker that ends without its result (killed by the system, most often for lack of memory
on a large campaign) stops the map with :class:`WorkerLost`, which says so, instead of the
parent waiting for it forever.

A task whose result is large (a projection basis of thousands of rows) writes it into a
:func:`shared_array` the parent made before the fork, instead of returning it through a pipe.
"""

from __future__ import annotations

import mmap
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import numpy as np

ENV_WORKERS = "PKM_DIAGNOSIS_WORKERS"
# fewer residual rows: the diagnosis's tasks take about a second or less in all, not worth a fork
PARALLEL_MIN_ROWS = 20_000
PROGRESS_AFTER_S = 5.0  # a progress line only once the candidates have taken this long

_TASK: Callable[[int], Any] | None = None  # what a forked worker runs (inherited)
_IN_WORKER = False  # set in each worker: its tasks run in it, without workers of their own


class WorkerLost(RuntimeError):
    """A worker process ended without returning its task's result."""


def _mark_worker() -> None:
    global _IN_WORKER
    _IN_WORKER = True


def _run(i: int) -> Any:
    assert _TASK is not None
    return _TASK(i)


def worker_count(n_rows: int, n_tasks: int) -> int:
    """How many processes evaluate ``n_tasks`` candidates of a problem of ``n_rows`` rows."""
    typed = os.environ.get(ENV_WORKERS, "").strip()
    if typed:
        try:
            wanted = int(typed)
        except ValueError:
            raise ValueError(f"{ENV_WORKERS}={typed!r} is not a whole number") from None
    else:
        wanted = (os.cpu_count() or 1) if n_rows >= PARALLEL_MIN_ROWS else 1
    usable = (
        "fork" in multiprocessing.get_all_start_methods()
        and not _IN_WORKER
        and not multiprocessing.current_process().daemon
    )
    return max(1, min(wanted, n_tasks)) if usable else 1


def shared_array(shape: tuple[int, ...]) -> np.ndarray:
    """A float array (zeros) in an anonymous shared mapping: what a forked worker writes into
    it, this process reads. It lives as long as an array refers to it."""
    size = int(np.prod(shape))
    buf = mmap.mmap(-1, max(size, 1) * 8)
    return np.frombuffer(buf, dtype=float, count=size).reshape(shape)


def map_in_order(fn: Callable[[int], Any], n_tasks: int, workers: int) -> Iterator[Any]:
    """``fn(0), fn(1), ...`` in that order, computed by ``workers`` forked processes (or
    here when 1); ``fn`` and what it reads are inherited by the fork, not pickled."""
    if workers <= 1 or n_tasks <= 1:
        for i in range(n_tasks):
            yield fn(i)
        return
    global _TASK
    _TASK = fn
    context = multiprocessing.get_context("fork")
    pool = ProcessPoolExecutor(workers, mp_context=context, initializer=_mark_worker)
    try:
        yield from pool.map(_run, range(n_tasks))
    except BrokenProcessPool as exc:
        raise WorkerLost(
            f"a worker process ended abruptly while {n_tasks} tasks were evaluated on "
            f"{workers} processes (killed by the system, most often for lack of memory; "
            "the memory a campaign needs is in the guide's 'What a campaign costs')"
        ) from exc
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        _TASK = None


def map_chunks(fn: Callable[[np.ndarray], Any], n_items: int, n_rows: int) -> Iterator[Any]:
    """``fn(indices)`` for consecutive chunks of ``range(n_items)`` (at least one, empty for no
    items), in order: side by side in worker processes on a long run (``n_rows`` residual
    rows, :func:`worker_count`), four chunks per worker so that none waits long for the last."""
    workers = worker_count(n_rows, n_items)
    chunks = np.array_split(np.arange(n_items), max(1, min(n_items, 4 * workers)))
    return map_in_order(lambda k: fn(chunks[k]), len(chunks), workers)


class Progress:
    """``diagnosis: 3 of 12 candidates evaluated (gain_error) after 7 s`` on stderr, once
    the work has taken PROGRESS_AFTER_S: nothing on a short run."""

    def __init__(self, what: str, total: int, workers: int = 1) -> None:
        self.what, self.total, self.workers = what, total, workers
        self.start = time.perf_counter()
        self.done = 0

    def step(self, name: str) -> None:
        self.done += 1
        elapsed = time.perf_counter() - self.start
        if elapsed >= PROGRESS_AFTER_S:
            on = f" on {self.workers} processes" if self.workers > 1 else ""
            print(
                f"diagnosis: {self.done} of {self.total} {self.what} evaluated ({name}) after "
                f"{elapsed:.0f} s{on}",
                file=sys.stderr,
                flush=True,
            )
