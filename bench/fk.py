"""Forward kinematics rates: single pose (twin.kinematics.forward) and batched
(twin.kinematics_batch.forward_batch, 10,000 poses, best of 2)."""

from __future__ import annotations

import time

import numpy as np

from twin.kinematics import forward
from twin.kinematics_batch import forward_batch
from twin.mechanism import Mechanism


def best_time(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def fk_rates(truth: Mechanism, cmds: np.ndarray, n_single: int = 200) -> dict:
    n_single = min(n_single, len(cmds))
    t_single = best_time(lambda: [forward(truth, c) for c in cmds[:n_single]], 1) / n_single
    big = np.tile(cmds, (10000 // len(cmds) + 1, 1))[:10000]
    t_batch = best_time(lambda: forward_batch(truth, big), 2) / len(big)
    return {
        "fk_single_ms": t_single * 1e3,
        "fk_batch_poses_per_s": 1.0 / t_batch,
        "fk_batch_speedup_vs_single": t_single / t_batch,
    }
