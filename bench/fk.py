"""Forward kinematics rates: single pose (twin.kinematics.single_pose.forward) and batched
(twin.kinematics.batch.forward_batch, 10,000 poses, best of 5): the compiled kernels (the
default) and the numpy path, timed alternately in the same run so that their ratio holds on a
loaded machine."""

from __future__ import annotations

import time

import numpy as np

from twin.kinematics.batch import forward_batch
from twin.kinematics.single_pose import forward
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
    t_batch = t_numpy = np.inf
    for _ in range(5):  # alternately, so both see the same load; best of 5 (the machine's
        # speed drifts by a quarter from one second to the next)
        t_batch = min(t_batch, best_time(lambda: forward_batch(truth, big), 1) / len(big))
        t_numpy = min(
            t_numpy, best_time(lambda: forward_batch(truth, big, compiled=False), 1) / len(big)
        )
    return {
        "fk_single_ms": t_single * 1e3,
        "fk_batch_poses_per_s": 1.0 / t_batch,
        "fk_batch_speedup_vs_single": t_single / t_batch,
        "fk_batch_numpy_poses_per_s": 1.0 / t_numpy,
        "fk_batch_compiled_speedup_vs_numpy": t_numpy / t_batch,
    }
