"""Finite differences of a calibration model's predicted targets, for the Jacobian tests."""

from __future__ import annotations

import numpy as np


def central_differences(model, x: np.ndarray, commands: np.ndarray, steps: np.ndarray):
    """(P*T*3, n): central differences of ``model.predict(x, commands).targets`` with the
    step ``steps[k]`` for parameter k, rows ordered as ``targets.reshape(-1)``."""
    cols = []
    for k, h in enumerate(steps):
        dx = np.zeros(len(x))
        dx[k] = h
        plus = model.predict(x + dx, commands).targets.reshape(-1)
        minus = model.predict(x - dx, commands).targets.reshape(-1)
        cols.append((plus - minus) / (2 * h))
    return np.array(cols).T
