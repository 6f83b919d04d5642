"""A synthetic diagnosis context for the diagnosis's unit tests: three slides and three
revolute actuators, random actuator Jacobians and targets, one reading per pose in time."""

from __future__ import annotations

import numpy as np

from calib.diagnosis.context import Context


def synthetic_context(
    rng: np.random.Generator, n: int, a: int, t: int, rows: np.ndarray | None = None
) -> Context:
    """``n`` poses of ``a`` actuators (the first three slides) and ``t`` targets, drawn from
    ``rng`` in one fixed order (commands, actuator Jacobian, targets); ``rows``: the readings
    kept (None: all)."""
    slide = np.array([True, True, True, False, False, False])
    commands = np.where(slide, rng.uniform(0.6, 1.1, (n, a)), rng.uniform(-1.0, 1.0, (n, a)))
    return Context(
        commands=commands,
        time=np.arange(n, dtype=float),
        previous=commands[0] - 0.01,
        is_slide=slide,
        actuator_names=tuple(f"a{i}" for i in range(a)),
        time_unit="pose",
        j_act=rng.normal(size=(n, 3 * t, a)),
        targets=rng.normal(size=(n, t, 3)),
        head=np.array([1.5, 0.0, 0.3]),
        **({} if rows is None else {"rows": rows}),
    )
