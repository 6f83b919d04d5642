"""A measurement plan: feasible candidates -> calibration poses by observability -> test poses
covering the workspace -> the program's order; and the twin's prediction of its accuracy
against the number of poses, beside random poses of the same pool."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.exceptions import IdentifiabilityError
from calib.fit.model import CalibrationModel
from calib.plan.candidates import Candidates
from calib.plan.feasibility import Feasibility, Rules, check_poses
from calib.plan.ordering import Order, order_program
from calib.plan.prediction import Prediction, draw_truth, predict
from calib.plan.selection import choose, cover, pose_blocks

CALIBRATION, TEST = "calibration", "test"


@dataclass(frozen=True)
class Plan:
    candidates: Candidates
    feasibility: Feasibility
    feasible: np.ndarray  # indices of the feasible candidates
    blocks: np.ndarray  # (F, 3T, r) projected Jacobian blocks of the feasible candidates
    targets: np.ndarray  # (F, T, 3) nominal target positions (m)
    calibration: list[int]  # into the feasible candidates
    test: list[int]
    criterion: str
    index_value: float
    order: Order

    @property
    def sequence(self) -> np.ndarray:
        """Candidate indices in program order."""
        picked = np.array(self.calibration + self.test, dtype=int)
        return self.feasible[picked[self.order.sequence]]

    @property
    def sets(self) -> np.ndarray:
        n_cal = len(self.calibration)
        return np.where(self.order.sequence >= n_cal, TEST, CALIBRATION)

    @property
    def commands(self) -> np.ndarray:
        return self.candidates.commands[self.sequence]

    @property
    def labels(self) -> list[str]:
        return [self.candidates.labels[k] for k in self.sequence]

    @property
    def identified_directions(self) -> int:
        return int(self.blocks.shape[2])


def make_plan(
    model: CalibrationModel,
    candidates: Candidates,
    rules: Rules,
    n: int,
    n_test: int,
    criterion: str = "d_optimal",
    seed: int = 0,
) -> Plan:
    """``n`` calibration and ``n_test`` test poses among the feasible candidates, ordered."""
    mech = model.nominal
    feas = check_poses(mech, candidates.commands, rules)
    feasible = np.flatnonzero(feas.ok)
    if len(feasible) < n + n_test:
        raise IdentifiabilityError(
            f"{n} + {n_test} poses asked but {feas.summary()}; give more candidates, a "
            "smaller margin, or move the tracker"
        )
    blocks, targets = pose_blocks(model, candidates.commands[feasible])
    rng = np.random.default_rng(seed)
    cal, value = choose(blocks, n, criterion, rng)
    test = cover(targets.reshape(len(feasible), -1), n_test, cal)
    picked = np.array(cal + test, dtype=int)
    ranges = mech.actuator_range[:, 1] - mech.actuator_range[:, 0]
    is_test = np.arange(len(picked)) >= len(cal)
    order = order_program(
        candidates.commands[feasible[picked]], ranges, mech.home_commands, is_test
    )
    return Plan(candidates, feas, feasible, blocks, targets, cal, test, criterion, value, order)


def accuracy_curve(
    model: CalibrationModel,
    plan: Plan,
    counts: list[int],
    sigma_m: float,
    draws: int,
    seed: int = 0,
    truth_scale: float = 1.0,
) -> list[Prediction]:
    """The predicted held-out accuracy (calib.plan.prediction) for each count: the pose set
    this planner picks at that count, and a fresh random set of the same feasible pool (not
    the test poses) per draw; every set is judged on the plan's test poses (or, without
    them, 50 feasible poses covering the workspace, not among the calibration pool's
    choices), against the same drawn truths."""
    cmds = plan.candidates.commands[plan.feasible]
    test = plan.test or cover(plan.targets.reshape(len(cmds), -1), min(50, len(cmds) // 3), [])
    pool = np.setdiff1d(np.arange(len(cmds)), test)
    rng = np.random.default_rng([seed, 1])
    truths = [draw_truth(model, rng, truth_scale) for _ in range(draws)]
    out = []
    for count in counts:
        if plan.test and count == len(plan.calibration):
            chosen = plan.calibration  # the program's own (the test poses were left out)
        else:
            rng_choice = np.random.default_rng(seed)
            chosen = [
                int(pool[k])
                for k in choose(plan.blocks[pool], count, plan.criterion, rng_choice)[0]
            ]
        out.append(
            predict(model, truths, [cmds[chosen]] * draws, cmds[test], sigma_m, seed, "plan")
        )
        random_sets = [cmds[rng.choice(pool, size=count, replace=False)] for _ in range(draws)]
        out.append(predict(model, truths, random_sets, cmds[test], sigma_m, seed, "random"))
    return out
