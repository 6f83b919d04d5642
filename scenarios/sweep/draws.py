"""A study's own draws as sweep tasks: the same engines as ``python -m scenarios sweep``.

A study that evaluates something over many draws (noise draws, truth draws) hands the draws
to :func:`map_draws` as tasks: a module-level function and plain arguments (paths, arrays,
seeds; each task builds its own model). The engine is :func:`sweep_engine.default_engine`:
in this process on a machine without Ray running, on Ray inside a sweep or when
``RAY_ADDRESS`` / ``PKM_ENGINE=ray`` ask for it. Results come back in the order of the
arguments whatever order the tasks finish in, so every engine gives the same numbers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from scenarios.progress import Progress
from scenarios.sweep.engine import default_engine


class DrawTaskError(RuntimeError):
    """The engine lost a task (a worker that died); the study cannot complete."""


def map_draws(
    fn: Callable[..., Any],
    args: Sequence[tuple[Any, ...]],
    progress: Progress | None = None,
    label: str = "draw tasks",
) -> list[Any]:
    """``[fn(*a) for a in args]`` on the default engine, in the order of ``args``."""
    engine = default_engine()
    out: list[Any] = [None] * len(args)
    try:
        for n, outcome in enumerate(engine.map(fn, args), start=1):
            if outcome.error is not None:
                raise DrawTaskError(f"{label} {outcome.index}: {outcome.error}")
            out[outcome.index] = outcome.value
            if progress is not None:
                progress.counter(f"{label} ({engine.name})", n, len(args))
    finally:
        engine.close()
    return out
