"""The plan beats random poses at equal N on the polisher (150 parameters, 109 directions
identifiable from its workspace): the twin's predicted held-out error over drawn truths,
near the fewest poses (16 poses, 144 equations), where the choice matters most."""

from __future__ import annotations

import numpy as np

from calib.fit import model_from_files
from calib.plan import Rules, accuracy_curve, make_plan, workspace_candidates

SIGMA_M = 1e-5


def test_plan_beats_random_poses_on_the_polisher():
    model = model_from_files("models/polisher.xml", "models/polisher.params.toml")
    cands = workspace_candidates(model.nominal, 400, np.random.default_rng(0))
    plan = make_plan(model, cands, Rules(), 16, 20)
    assert plan.identified_directions == 109
    planned, random = (p.stats() for p in accuracy_curve(model, plan, [16], SIGMA_M, draws=4))
    assert planned["failed"] == random["failed"] == 0
    # the model's own error over the workspace (the calibrated machine against the drawn
    # truth) is what a plan is for; the held-out readings' error adds the tracker noise
    # (0.017 mm 3D at 0.01 mm per coordinate), which over 4 draws decides nothing: measured
    # 0.0203 vs 0.0199 mm (verify's median) where the model's is 0.0091 vs 0.0133 mm
    print({k: (planned[k], random[k]) for k in ("median_mm", "model_median_mm", "model_p90_mm")})
    for key in ("model_median_mm", "model_p90_mm"):
        assert planned[key] < random[key], key
