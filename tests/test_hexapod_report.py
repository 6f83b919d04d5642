"""hexapod_paper's report says what its run's numbers say: where the truth came from, and
whether the worst estimate is within what the noise explains (fed different numbers, the
sentences change with them)."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from scenarios.studies.hexapod_paper.report import (
    deviation_sentence,
    largest_deviation_p,
    noise_free_sentence,
    report,
    truth_sentence,
)

CASE = {
    "n_poses": 256,
    "noise": "paper",
    "max_abs_mm": 0.28,
    "worst_parameter": "leg5.base.dz",
    "worst_std_error_mm": 0.097,
    "worst_over_std": 2.89,
    "max_abs_over_std": 2.89,
    "n_estimated": 54,
    "strongest_correlations": [],
    "iterations": 5,
    "condition_number": 1e3,
}


def test_largest_deviation_probability_is_sidak():
    # one estimate: P(|z| >= 1.96) = 0.05; 54 of them: 1 - 0.95^54
    assert largest_deviation_p(1.959964, 1) == pytest.approx(0.05, rel=1e-5)
    assert largest_deviation_p(1.959964, 54) == pytest.approx(1 - 0.95**54, rel=1e-5)
    assert largest_deviation_p(0.0, 54) == pytest.approx(1.0)


def test_the_verdict_follows_the_deviation():
    calm = deviation_sentence(CASE)
    assert "2.89 standard errors" in calm and "consistent with the noise" in calm
    far = deviation_sentence({**CASE, "max_abs_over_std": 4.0, "worst_over_std": 4.0})
    assert "4.00 standard errors" in far and "larger than linear noise propagation" in far
    assert "consistent" not in far  # 4 standard errors is not what the noise gives
    few = deviation_sentence({**CASE, "max_abs_over_std": 4.0, "n_estimated": 3})
    assert "larger" in few  # among 3 estimates, 4 standard errors is rarer still
    many = deviation_sentence({**CASE, "max_abs_over_std": 3.5, "n_estimated": 5000})
    assert "consistent" in many  # the largest of 5000 is often 3.5
    assert "leg5.base.dz" in calm
    assert "leg1.length" in deviation_sentence({**CASE, "worst_parameter": "leg1.length"})


def test_the_truth_sentence_names_the_source():
    paper = truth_sentence({"kind": "values_file", "file": "truth/hexapod_table2.toml"}, 54)
    assert "paper's Table 2" in paper
    other = truth_sentence({"kind": "values_file", "file": "truth/mine.toml"}, 54)
    assert "mine.toml" in other and "not the paper's" in other
    drawn = truth_sentence(
        {"kind": "random", "seed": 7, "random": {"distribution": "uniform", "length_mm": 0.5}},
        54,
    )
    assert "random draw" in drawn and "seed 7" in drawn and "length_mm 0.5" in drawn
    assert "Table 2 (actual" not in drawn


def test_a_report_of_a_random_truth_does_not_claim_the_papers(tmp_path):
    root = Path(__file__).resolve().parent.parent
    # the shipped run's summary shape, written by a fake run: the report's own fields only
    summary = {
        "paper": json.loads(json.dumps(_paper())),
        "cases": {"random_many": CASE},
        "n_parameters": 54,
        "n_identifiable": 54,
        "runtime_s": 1.0,
        "truth_source": {"kind": "random", "seed": 3, "random": {"distribution": "normal"}},
    }
    text = report(summary)
    assert "random draw" in text and "the paper's Table 2 (actual" not in text
    summary2 = copy.deepcopy(summary)
    summary2["truth_source"] = {"kind": "values_file", "file": "truth/hexapod_table2.toml"}
    summary2["cases"]["random_many"] = {**CASE, "max_abs_over_std": 5.0}
    text2 = report(summary2)
    assert "the paper's Table 2 (actual" in text2 and "larger than linear" in text2
    assert (root / "scenarios" / "truth" / "hexapod_table2.toml").is_file()


def _paper() -> dict:
    from scenarios.studies.hexapod_paper.study import PAPER

    return PAPER


def test_the_noise_free_sentence_follows_the_recovery():
    exact = {**CASE, "n_poses": 9, "max_abs_mm": 2.5e-10, "residual_rms_mm": 1e-13}
    assert "recovers the errors to round-off (largest deviation 2.5e-10 mm)" in (
        noise_free_sentence(exact)
    )
    other_root = {**exact, "max_abs_mm": 3.2, "worst_parameter": "leg2.length"}
    text = noise_free_sentence(other_root)
    assert "does not recover" in text and "3.2 mm on leg2.length" in text
    assert "another exact root" in text
    short = {**other_root, "residual_rms_mm": 0.01}
    assert "stopped short" in noise_free_sentence(short)
    assert "54 equations" in noise_free_sentence(exact)


def _optimal_summary(n_optimal: int, n_exchange: int) -> dict:
    """The optimal_poses summary's fields the report reads, with the counts given."""
    row = {
        "n_poses": n_optimal,
        "index_condition": 10.0,
        "param_max_abs_mm": 0.01,
        "verify_pos_peak_mm": 0.02,
        "verify_ori_peak_deg": 0.004,
        "failed_draws": 0,
    }
    return {
        "index": "condition",
        "n_optimal": n_optimal,
        "n_noise_draws": 3,
        "optimal": row,
        "exchange": {**row, "n_poses": n_exchange},
        "random_same_count": row,
        "random_256": {**row, "n_poses": 256},
        "paper_table4": {
            "random_256": {"pos_peak_mm": 0.028, "ori_peak_deg": 0.0069},
            "optimal_29": {"pos_peak_mm": 0.0212, "ori_peak_deg": 0.0047},
            "n_optimal": 29,
        },
        "index_counts": [9, 10],
        "index_by_count": [5.0, 4.0],
    }


def test_optimal_poses_report_says_the_counts_it_ran():
    """The exchange design's count is the greedy set's (22 in the shipped run), not the
    paper's 29; the figure's title says how many of the starts it draws."""
    from scenarios.studies.optimal_poses.report import index_figure_title
    from scenarios.studies.optimal_poses.report import report as poses_report

    text = poses_report(_optimal_summary(22, 22))
    assert "started from the greedy set, at the greedy selection's count, 22 poses" in text
    assert "the paper's optimal set has 29." in text
    assert "same count as the paper" not in text
    text = poses_report(_optimal_summary(29, 31))
    assert "at 31 poses (the greedy selection stops at 29)" in text
    assert "the paper's optimal set has 29." in text
    text = poses_report(_optimal_summary(29, 29))
    assert "the paper's optimal set has the same 29." in text
    assert index_figure_title("condition", 30, 5) == (
        "hexapod: condition index of the greedy selection (the best of 30; 5 of 30 starts drawn)"
    )
    assert index_figure_title("d_optimality", 4, 4).endswith("(the best of 4; all 4 starts drawn)")
