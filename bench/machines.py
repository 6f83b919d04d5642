"""The three machines of the benchmark: nominal model, error model, a truth and a dataset.

* hexapod: models/hexapod_rrrprr, the paper's Table 2 truth, 256 random reachable poses,
  measured with pose noise (as the benchmark always did);
* polisher: models/polisher, a uniform truth like liu_vs_ols's, its fine plan (two layers of
  7 x 7 nodes at +-60 mm), tracker noise 5 um; only part of its 150 parameters is
  identifiable, so identification fixes the rest;
* arm: models/arm6r, a uniform truth like serial_arm's, 256 joint commands uniform over 80 %
  of each range, tracker noise 5 um, readings in the base frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.fit.observations import Observations
from scenarios.config import REPO_ROOT
from scenarios.truth_draw import TruthSpec, draw_truth
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.kinematics.batch import forward_batch
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet
from twin.tracker import PoseNoise, Tracker, TrackerNoise
from twin.workspace import commands_for_poses, layer_poses, random_poses, uniform_commands


@dataclass(frozen=True)
class BenchMachine:
    name: str
    nominal: Mechanism
    params: ParameterSet
    truth: Mechanism
    obs: Observations
    unidentifiable: str  # "raise" (all identifiable) or "fix"
    plan: str  # the poses, in words


def _tracker_obs(truth: Mechanism, cmds: np.ndarray, rng: np.random.Generator) -> Observations:
    tracker = Tracker(position_m=(2.5, 0.0, 0.5), noise=TrackerNoise("gaussian", 5e-6, 0.0))
    return Observations(cmds, tracker.measure_averaged(forward_batch(truth, cmds).targets, rng))


def _load(xml: str, params_file: str) -> tuple[Mechanism, ParameterSet]:
    nominal = Mechanism.from_xml(REPO_ROOT / xml)
    return nominal, load_parameter_set(REPO_ROOT / params_file, nominal.model)


def hexapod() -> BenchMachine:
    nominal, params = _load("models/hexapod_rrrprr.xml", "models/hexapod_rrrprr.params.toml")
    truth_v = load_values(REPO_ROOT / "scenarios/truth/hexapod_table2.toml", params)
    truth = Mechanism(params.inject(nominal.model, truth_v))
    rng = np.random.default_rng(7)
    _, cmds = random_poses(nominal, 256, rng)
    meas = measure(truth, cmds, Tracker(noise=TrackerNoise.none()), rng, PoseNoise())
    obs = Observations(cmds, meas.readings.mean(axis=2))
    return BenchMachine(
        "hexapod", nominal, params, truth, obs, "raise", "256 random reachable poses"
    )


def polisher() -> BenchMachine:
    nominal, params = _load("models/polisher.xml", "models/polisher.params.toml")
    rng = np.random.default_rng(2018)
    spec = TruthSpec("uniform", 1.0, 0.1, 3.0, 0.1)
    truth = nominal.with_model(params.inject(nominal.model, draw_truth(params, spec, rng)))
    poses = layer_poses(nominal, [0.06, -0.06], 7, (0.25, 0.25))
    cmds = commands_for_poses(nominal, poses)
    return BenchMachine(
        "polisher",
        nominal,
        params,
        truth,
        _tracker_obs(truth, cmds, rng),
        "fix",
        "two layers of 7 x 7 nodes (z = +-60 mm), as liu_vs_ols's fine plan",
    )


def arm() -> BenchMachine:
    nominal, params = _load("models/arm6r.xml", "models/arm6r.params.toml")
    rng = np.random.default_rng(11)
    spec = TruthSpec("uniform", 0.3, 0.03, 0.0, 0.05)
    truth = nominal.with_model(params.inject(nominal.model, draw_truth(params, spec, rng)))
    cmds = uniform_commands(nominal, 256, 0.8, rng)
    return BenchMachine(
        "arm",
        nominal,
        params,
        truth,
        _tracker_obs(truth, cmds, rng),
        "fix",
        "256 joint commands uniform over 80 % of each range",
    )


MACHINES = {"hexapod": hexapod, "polisher": polisher, "arm": arm}
