"""Speed benchmark (``make bench``): numbers written to results/bench.json, compared as ratios.

* closed-chain forward kinematics of the hexapod: single pose (Newton, one MjData) and
  batched (mujoco.batch + vectorised Newton), poses per second and their ratio;
* identification of the 54 parameters from 256 noisy poses with our Levenberg-Marquardt and
  implicit-function Jacobian, against scipy.optimize.least_squares with a finite-difference
  Jacobian (what a user would write first), in the same run;
* the whole scenarios.
Targets: >= 10,000 batched FK poses/s on 2 cores; hexapod_paper under 30 s; liu_vs_ols
(Monte Carlo included) under 60 s. ``meets_targets`` in the file says which are met.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from calib.identify import Observations, identify
from calib.model import CalibrationModel
from scenarios.config import REPO_ROOT
from scenarios.results import write_json_atomic
from scenarios.runner import run_scenario
from twin.kinematics import forward
from twin.kinematics_batch import forward_batch
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.parameter_file import load_parameter_set, load_values
from twin.tracker import PoseNoise, Tracker, TrackerNoise
from twin.workspace import random_poses


def _time(fn, repeat: int = 3) -> float:
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    out: dict = {"cpu_count": os.cpu_count()}
    nominal = Mechanism.from_xml(REPO_ROOT / "models/hexapod_rrrprr.xml")
    params = load_parameter_set(REPO_ROOT / "models/hexapod_rrrprr.params.toml", nominal.model)
    truth_v = load_values(REPO_ROOT / "scenarios/truth/hexapod_table2.toml", params)
    truth = Mechanism(params.inject(nominal.model, truth_v))
    rng = np.random.default_rng(7)
    _, cmds = random_poses(nominal, 256, rng)

    # forward kinematics
    n_single = 200
    t_single = _time(lambda: [forward(truth, c) for c in cmds[:n_single]], 1) / n_single
    big = np.tile(cmds, (40, 1))[:10000]
    t_batch = _time(lambda: forward_batch(truth, big), 2) / len(big)
    out["fk_single_ms"] = t_single * 1e3
    out["fk_batch_poses_per_s"] = 1.0 / t_batch
    out["fk_batch_speedup_vs_single"] = t_single / t_batch
    print(
        f"FK single {t_single * 1e3:.3f} ms/pose, batched {1 / t_batch:.0f} poses/s "
        f"({t_single / t_batch:.1f}x)"
    )

    # identification, ours vs scipy least_squares with a finite-difference Jacobian
    tracker = Tracker(noise=TrackerNoise.none())
    meas = measure(truth, cmds, tracker, rng, PoseNoise())
    obs = Observations(cmds, meas.readings.mean(axis=2))
    model = CalibrationModel(nominal, params)
    t0 = time.perf_counter()
    ours = identify(model, obs)
    t_ours = time.perf_counter() - t0

    def resid(x: np.ndarray) -> np.ndarray:
        return (obs.measured - model.predict(x, cmds).targets).reshape(-1)

    t0 = time.perf_counter()
    base = least_squares(resid, np.zeros(len(params)), jac="2-point", method="lm", x_scale="jac")
    t_base = time.perf_counter() - t0
    out["identify_256_ours_s"] = t_ours
    out["identify_256_scipy_fd_s"] = t_base
    out["identify_speedup_vs_scipy_fd"] = t_base / t_ours
    out["identify_ours_vs_scipy_max_abs_diff_mm"] = float(
        np.max(np.abs(ours.values - base.x)) * 1e3
    )
    print(
        f"identify 256 poses: ours {t_ours:.2f} s, scipy FD {t_base:.2f} s "
        f"({t_base / t_ours:.1f}x), estimates differ by "
        f"{out['identify_ours_vs_scipy_max_abs_diff_mm']:.2g} mm"
    )

    # whole scenarios
    for name in ("hexapod_paper", "liu_vs_ols", "polisher_identifiability"):
        t0 = time.perf_counter()
        run_scenario(name, quiet=True)
        out[f"scenario_{name}_s"] = time.perf_counter() - t0
        print(f"scenario {name} {out[f'scenario_{name}_s']:.1f} s")
    out["targets"] = {
        "fk_batch_poses_per_s": 10000,
        "scenario_hexapod_paper_s": 30,
        "scenario_liu_vs_ols_s": 60,
    }
    out["meets_targets"] = {
        "fk_batch_poses_per_s": out["fk_batch_poses_per_s"] >= 10000,
        "scenario_hexapod_paper_s": out["scenario_hexapod_paper_s"] <= 30,
        "scenario_liu_vs_ols_s": out["scenario_liu_vs_ols_s"] <= 60,
    }
    path = write_json_atomic(Path(REPO_ROOT / "results" / "bench.json"), out)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
