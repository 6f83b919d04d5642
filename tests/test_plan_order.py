"""The program's order and file: travel, interleaving, approach sides, selection and cover,
the CSV read back; and the command's refusals (exit 2 naming the cause)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from calib.analysis.observability_indices import observability
from calib.cli.commands import main
from calib.fit import model_from_files
from calib.plan import Rules, file_candidates, make_plan, workspace_candidates
from calib.plan.ordering import approach_directions, order_program
from calib.plan.selection import choose, cover
from twin.mechanism import Mechanism

ARM = ["--model", "models/arm6r.xml", "--errors", "models/arm6r.params.toml"]


def test_nearest_neighbour_on_a_line_travels_the_span_once():
    # poses on one line in shuffled order, home at one end: the tour walks straight out, so
    # its travel is the span (1 range width), the shuffled order's is far more
    x = np.random.default_rng(1).permutation(np.linspace(0.0, 1.0, 11))
    commands = np.stack([x, 0.5 * x], axis=1)
    o = order_program(commands, np.ones(2), np.zeros(2), np.zeros(11, bool))
    assert np.allclose(commands[o.sequence][:, 0], np.linspace(0, 1, 11))
    assert o.travel == pytest.approx(1.0)
    assert o.travel_unordered == pytest.approx(np.sum(np.abs(np.diff(np.r_[0.0, x]))))


def test_test_poses_spread_evenly_and_each_actuator_comes_from_both_sides():
    rng = np.random.default_rng(2)
    commands = rng.uniform(-1, 1, size=(50, 4))
    is_test = np.zeros(50, bool)
    is_test[rng.choice(50, 10, replace=False)] = True
    o = order_program(commands, np.full(4, 2.0), np.zeros(4), is_test)
    assert sorted(o.sequence.tolist()) == list(range(50))
    where = np.flatnonzero(is_test[o.sequence])
    # 40 calibration poses, 10 test poses: one test pose in each run of 4 calibration poses
    assert np.all(np.diff(where) <= 6) and where[0] <= 3 and where[-1] >= 45
    sets = np.where(is_test[o.sequence], "test", "calibration")
    for s in ("test", "calibration"):
        assert np.all(np.abs(o.directions[sets == s].sum(axis=0)) <= 1)
    # the directions that were not flipped are those of the moves into the poses
    moves = np.diff(np.vstack([np.zeros(4), commands[o.sequence]]), axis=0)
    assert np.mean(o.directions == np.where(moves < 0, -1, 1)) > 0.7


def test_balancing_flips_the_smallest_moves_of_the_majority():
    # five moves up (sizes 5, 4, 3, 2, 1): balance needs two flipped, the two smallest
    commands = np.cumsum([[5.0], [4.0], [3.0], [2.0], [1.0]], axis=0)
    dirs = approach_directions(commands, np.zeros(1), np.array(["calibration"] * 5))
    assert dirs[:, 0].tolist() == [1, 1, 1, -1, -1]


def test_exchange_reaches_a_d_optimum_no_single_swap_improves():
    rng = np.random.default_rng(4)
    blocks = rng.normal(size=(40, 3, 5))
    chosen, value = choose(blocks, 6, "d_optimal", rng)
    assert value == pytest.approx(observability(np.vstack(blocks[chosen]), "d_optimality"))
    for pos in range(6):
        for j in set(range(40)) - set(chosen):
            swap = [*chosen[:pos], j, *chosen[pos + 1 :]]
            worse = observability(np.vstack(blocks[swap]), "d_optimality")
            assert worse <= value + 1e-8 * abs(value)


def test_cover_takes_the_centre_then_the_farthest():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [-1.5, 0.0], [0.1, 0.0], [0.0, 3.0]])
    assert cover(pts, 3, exclude=[3]) == [
        0,
        2,
        4,
    ]  # centroid (-0.125, 0.75): nearest (0, 0); then (0, 3); then (-1.5, 0)


def test_program_file_reads_back_as_candidates_with_the_same_commands(tmp_path):
    model = model_from_files("models/hexapod_rrrprr.xml", "models/hexapod_rrrprr.params.toml")
    cands = workspace_candidates(model.nominal, 150, np.random.default_rng(0))
    out = tmp_path / "p.csv"
    args = ["plan", "--model", "models/hexapod_rrrprr.xml", "--errors"]
    args += ["models/hexapod_rrrprr.params.toml", "--n", "15", "--n-test", "5"]
    assert main([*args, "--n-candidates", "150", "--out", str(out)]) == 0
    plan = make_plan(model, cands, Rules(), 15, 5)  # the same draw: seed 0
    back = file_candidates(out, model.nominal, None)
    assert back.labels == tuple(plan.labels)
    assert np.allclose(back.commands, plan.commands, rtol=0, atol=1e-9)  # mm to 10 digits
    test = file_candidates(out, model.nominal, "test")
    assert len(test) == 5
    rows = list(csv.DictReader(out.open()))
    assert [r["set"] for r in rows] == [str(s) for s in plan.sets]
    summary = json.loads(out.with_suffix(".json").read_text())
    assert summary["pose_ids"] == plan.labels and summary["n_test"] == 5


def test_bad_input_exits_2_naming_the_cause(tmp_path, capsys):
    out = str(tmp_path / "p.csv")
    assert main(["plan", *ARM, "--n", "5", "--candidates", "nope.csv", "--out", out]) == 2
    assert "file not found: nope.csv" in capsys.readouterr().err
    assert main(["plan", *ARM, "--n", "5", "--set", "calibration", "--out", out]) == 2
    assert "give --candidates FILE" in capsys.readouterr().err
    assert main(["plan", *ARM, "--n", "500", "--n-candidates", "50", "--out", out]) == 2
    assert "500 + 125 poses asked but" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("pose_id,cmd:A1\n1,0\n")
    assert main(["plan", *ARM, "--n", "5", "--candidates", str(bad), "--out", out]) == 2
    assert "no column(s) ['cmd:A2'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["plan", *ARM, "--n", "5", "--tracker-at", "1,2", "--out", out])
    assert "x,y,z" in capsys.readouterr().err


def test_workspace_candidates_of_a_serial_arm_lie_within_the_ranges():
    mech = Mechanism.from_xml("models/arm6r.xml")
    c = workspace_candidates(mech, 200, np.random.default_rng(0))
    lo, hi = mech.actuator_range.T
    assert np.all((c.commands >= lo) & (c.commands <= hi))


def test_paper_criterion_reports_the_condition_number_of_its_choice():
    rng = np.random.default_rng(5)
    blocks = rng.normal(size=(60, 3, 5))
    chosen, value = choose(blocks, 8, "paper", rng)
    assert len(set(chosen)) == 8
    assert value == pytest.approx(observability(np.vstack(blocks[chosen]), "condition"))
    # the greedy's choice is better conditioned than a random set of the same size
    other = np.random.default_rng(6).choice(60, 8, replace=False)
    assert value < observability(np.vstack(blocks[other]), "condition")
