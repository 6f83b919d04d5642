"""Stages scored on the same machine state (scenarios.studies.liu_vs_ols.pipeline.score).

A truth with a strong thermal drift (the limbs grow 0.5 um per metre with every pose
measured) and two identical estimators: scored one after the other as the sequence runs on,
the later one meets a warmer machine and looks worse; scored from the same clock they come
out equal, and the "OLS again" control equals OLS.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from scenarios.config import Scenario, load_scenario
from scenarios.studies.liu_vs_ols.draws import draw_task
from scenarios.studies.liu_vs_ols.pipeline import (
    CONTROL,
    calibrate,
    make_bench,
    order_control_um,
    score,
    stage_commands,
    with_control,
)

TWINS = ["ols", {"label": "ols_twin", "method": "ols"}]  # two identical estimators


def drifting(rate_k_per_pose: float = 0.05) -> Scenario:
    """liu_vs_ols with a thermal drift 50 times the scenario's and no other effect."""
    base = load_scenario("liu_vs_ols")
    data = copy.deepcopy(base.data)
    data["truth"]["effects"] = [
        {"kind": "thermal_growth", "start_K": 0.0, "rate_K_per_pose": rate_k_per_pose}
    ]
    data["scoring"] = {"nodes_per_side": 4}
    return Scenario(base.name, base.study, base.path, data, base.schema)


@pytest.fixture(scope="module")
def calibrated():
    bench = make_bench(drifting())
    cal = calibrate(bench, TWINS)
    poses = {g: bench.poses(g, 4) for g in ("calibration", "test")}
    cmds = {g: with_control(stage_commands(bench, cal, p)) for g, p in poses.items()}
    return bench, cal, poses, cmds


def test_identical_estimators_score_equally_on_a_drifting_machine(calibrated):
    bench, cal, poses, cmds = calibrated
    np.testing.assert_array_equal(cal.estimates["ols"][0].x, cal.estimates["ols_twin"][0].x)
    start = bench.clock[0]
    layers, _ = score(bench, poses, cmds)
    for group in ("calibration", "test", "all"):
        for stage in ("ols_twin", CONTROL):
            assert layers[group][stage] == layers[group]["ols"], (group, stage)
    assert order_control_um(layers) == 0.0
    assert bench.clock[0] == start + len(poses["calibration"])  # the clock moves on after


def test_the_same_estimators_scored_in_sequence_differ(calibrated):
    """The drift is strong enough to decide a comparison when the clock runs through scoring:
    the fair scoring above is what makes the two equal."""
    bench, _, poses, cmds = calibrated
    layers, _ = score(bench, poses, cmds, clock="sequential")
    test = layers["test"]
    assert abs(test["ols_twin"]["pos_mean_mm"] - test["ols"]["pos_mean_mm"]) > 1e-3  # > 1 um
    assert abs(order_control_um(layers)) > 1.0  # um
    with pytest.raises(ValueError, match="clock"):
        score(bench, poses, cmds, clock="interleaved")


def test_the_draw_study_scores_its_stages_on_one_machine_state():
    """One draw of liu_vs_ols_draws (the scenario's own effects): the control equals OLS."""
    out = draw_task("liu_vs_ols_draws", 2018, ["ols", "liu"], 3)
    for group in ("calibration", "test", "all"):
        assert out["layers"][group][CONTROL] == out["layers"][group]["ols"]
