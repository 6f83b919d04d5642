"""Pose selection: the paper's greedy algorithm, the exchange design, and their scenario."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from recording_faces import assert_every_face_has_data

from calib.analysis.observability_indices import observability
from calib.analysis.pose_selection import (
    Selection,
    exchange,
    greedy,
    paper_selection,
    stopping_count,
)
from calib.exceptions import IdentifiabilityError
from scenarios.runner import run_scenario
from twin.exceptions import WorkspaceError
from twin.mechanism import Mechanism
from twin.workspace import boundary_poses

ROOT = Path(__file__).resolve().parent.parent


def _blocks(seed: int = 0, n: int = 30, m: int = 8):
    rng = np.random.default_rng(seed)
    return [rng.normal(size=(3, m)) * rng.uniform(0.1, 2.0, size=m) for _ in range(n)]


def test_greedy_adds_the_best_pose_each_time():
    blocks = _blocks()
    sel = greedy(blocks, [0, 1, 2], 8, "condition")
    for k in range(3, 8):
        chosen = sel.indices[:k]
        values = {
            i: observability(np.vstack([blocks[j] for j in [*chosen, i]]), "condition")
            for i in range(len(blocks))
            if i not in chosen
        }
        assert sel.indices[k] == min(values, key=values.get)
    assert greedy(blocks, [0, 1, 2], 8, "condition").indices == sel.indices  # deterministic


def test_round_off_ties_go_to_the_lower_index():
    """A twin of each candidate (rows reversed and negated: the same Gram matrix, the same
    index up to round-off) is never preferred to the candidate it copies."""
    blocks = _blocks(3, n=12)
    twins = blocks + [-b[::-1] for b in blocks]
    for name in ("condition", "d_optimality"):
        sel = greedy(twins, [0, 1, 2], 10, name)
        for k, i in enumerate(sel.indices):
            if i >= len(blocks):
                assert i - len(blocks) in sel.indices[:k]
        assert sel.indices == greedy(blocks + blocks, [0, 1, 2], 10, name).indices
        assert sel.index_by_count == pytest.approx(
            greedy(blocks + blocks, [0, 1, 2], 10, name).index_by_count, rel=1e-12
        )


def test_exchange_never_worsens_d_optimality():
    blocks = _blocks(1)
    start = list(range(6))
    chosen, value = exchange(blocks, start, "d_optimality")
    before = observability(np.vstack([blocks[i] for i in start]), "d_optimality")
    assert value >= before and len(chosen) == len(start) == len(set(chosen))


def test_paper_selection_keeps_the_best_start():
    blocks = _blocks(2)
    best, runs = paper_selection(blocks, np.random.default_rng(0), 4, 3, 8, "condition")
    assert best.final == min(r.final for r in runs)


def test_stopping_count():
    curve = [100.0, 50.0, 30.0, 29.9, 29.8, 29.8, 29.7, 29.7]
    assert stopping_count(Selection(list(range(8)), curve, 9, "condition"), 0.01, 3) == 11


def test_too_few_candidates():
    with pytest.raises(IdentifiabilityError, match="too few candidates"):
        greedy(_blocks(n=5), [0], 6)
    with pytest.raises(IdentifiabilityError, match="cannot identify"):
        paper_selection(_blocks(n=2, m=8), np.random.default_rng(0), 1, 1, 2)


def test_boundary_poses_lie_on_the_reachable_boundary():
    mech = Mechanism.from_xml(ROOT / "models/hexapod_rrrprr.xml")
    poses, cmds = boundary_poses(mech)
    assert poses.shape == (64, 6)
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    # each pose touches a stroke limit (it is on the boundary), none goes past one
    at_limit = np.min(np.minimum(np.abs(cmds - lo), np.abs(cmds - hi)), axis=1)
    assert np.all(at_limit < 2e-4)
    assert np.all((cmds >= lo - 1e-9) & (cmds <= hi + 1e-9))


def test_unreachable_workspace_centre_raises():
    mech = Mechanism.from_xml(ROOT / "models/hexapod_rrrprr.xml")
    mech.workspace_min = mech.workspace_min + np.array([0, 0, 0.2, 0, 0, 0])
    mech.workspace_max = mech.workspace_max + np.array([0, 0, 0.2, 0, 0, 0])
    with pytest.raises(WorkspaceError, match="centre is not reachable"):
        boundary_poses(mech)


DRAWS = 8  # noise draws of the quick run: the sets compared over the same draws' means


@pytest.mark.accuracy
def test_optimal_poses_scenario_quick(tmp_path):
    text = (ROOT / "scenarios/studies/optimal_poses/optimal_poses.toml").read_text()
    text = text.replace("noise_draws = 100", f"noise_draws = {DRAWS}")
    text = text.replace("random_starts = 30 ", "random_starts = 2 ")
    text = text.replace('values_file = "truth/', f'values_file = "{ROOT}/scenarios/truth/')
    path = tmp_path / "optimal_quick.toml"
    path.write_text(text)
    s, out = run_scenario(str(path), tmp_path, quiet=True)
    assert s["n_noise_draws"] == DRAWS
    # the index by pose count is the report's figure (its plateau marked), static; the
    # selected poses the one timeline
    views = {v["name"] for v in assert_every_face_has_data(out / f"{out.name}.rrd")}
    assert "condition index by pose count" in views
    assert len(s["index_by_count"]) == 40 - 9 + 1
    assert 9 < s["n_optimal"] <= 40
    opt, rand = s["optimal"], s["random_same_count"]
    assert opt["n_poses"] == rand["n_poses"] == s["n_optimal"]
    for name in ("optimal", "random_same_count"):
        assert s[name]["failed_draws"] == 0
    # the selected set is better conditioned than random poses of the same count (what the
    # selection minimises) ...
    assert opt["index_condition"] < rand["index_condition"]
    # ... and what that is for: identified over the same noise draws (each draw perturbs
    # every set in turn), the selected poses leave a smaller peak pose error on the
    # verification grid than random poses of the same count, in position and orientation
    for key in ("verify_pos_peak_mm", "verify_ori_peak_deg"):
        assert opt[key] < rand[key], (key, opt[key], rand[key])
    assert opt["param_max_abs_mm"] < rand["param_max_abs_mm"]


def test_candidate_set_with_unreachable_poses_is_refused():
    """A user's candidate list: each pose must be inside the box and within the strokes."""
    from twin.workspace import commands_for_poses

    mech = Mechanism.from_xml(ROOT / "models/hexapod_rrrprr.xml")
    poses = np.array([[0, 0, 0.22, 0, 0, 0], [0, 0, 0.30, 0, 0, 0], [0, 0, 0.24, 0.26, 0.26, 0]])
    with pytest.raises(WorkspaceError, match="pose 1: pose z = 300 mm is outside the workspace"):
        commands_for_poses(mech, poses)
    with pytest.raises(WorkspaceError, match=r"pose 2: .*not reachable.*stroke"):
        commands_for_poses(mech, poses[[0, 0, 2]])
