"""liu_vs_ols's report says what the run's numbers say: fed other numbers, its sentences change.

The summaries here are made up (no scenario runs): each test changes the numbers a sentence
is made from and checks that the sentence follows them.
"""

from __future__ import annotations

import copy

import pytest

from scenarios.studies.liu_regime.report import report as regime_report
from scenarios.studies.liu_vs_ols.pipeline import PAPER
from scenarios.studies.liu_vs_ols.report import report


def _row(mean: float, mx: float) -> dict[str, float]:
    return {"pos_mean_mm": mean, "pos_max_mm": mx, "ori_max_deg": 0.01, "ori_mean_deg": 0.004}


def summary() -> dict:
    test = {
        "uncalibrated": _row(14.2, 15.7),
        "coarse": _row(0.113, 0.174),
        "ols": _row(0.0359, 0.0972),
        "liu": _row(0.0359, 0.0975),
        "liu_paper_deg": _row(0.0361, 0.1003),
        "loop": _row(0.0134, 0.0269),
        "ols_again": _row(0.0359, 0.0972),
    }
    return {
        "paper": PAPER,
        "truth_random": {"distribution": "uniform", "translation_mm": 0.04},
        "truth_effects": ["joint_backlash", "thermal_growth", "lead_error"],
        "n_source_errors": 150,
        "n_identifiable": 51,
        "coarse_iterations": 2,
        "coarse_converged": True,
        "runtime_s": 9.0,
        "liu_bias_d": 4.966e-12,
        "liu_k": 5.506e-12,
        "liu_d": 4.966e-12 / 5.506e-12,
        "estimators": {
            "liu": {"bias_parameter": 4.966e-12, "scale_parameter": 5.506e-12, "notes": []},
            "liu_paper_deg": {"bias_parameter": 0.9318, "scale_parameter": 1.0, "notes": []},
        },
        "tracker_sigma_mm": 0.005,
        "scoring": {
            "clock": "same",
            "start_pose": 148,
            "order_control_um": 0.0,
            "order_control_all_um": 0.0,
        },
        "layers": {"test": test, "calibration": copy.deepcopy(test), "all": copy.deepcopy(test)},
        "monte_carlo_runs": 10000,
        "noise_only_test_um": {
            "ols": {"mean": 1.92, "max": 4.65},
            "liu_paper_deg": {"mean": 1.59, "max": 3.81},
        },
        "sigma_ols": 76.3,
        "sigma_liu": 47.8,
        "eta_percent": 37.3,
        "eta_percent_liu_k1": 37.8,
        "eta_at_used_d_percent": {"liu": 6.4, "liu_k1": 7.2, "liu_paper_deg": 6.8},
        "paper_units": {"eta_percent": 36.6, "eta_percent_rad": 36.6},
        "loop": {
            "diagnosed_effect": "backlash",
            "reason": "backlash lowers the held-out error",
            "residual_rms_before_mm": 0.080,
            "residual_rms_after_mm": 0.014,
            "noise_floor_rms_mm": 0.00866,
            "lm_iterations": 18,
            "coefficients": {"backlash.theta4.half_play": 1.2e-4},
            "coefficient_std": {"backlash.theta4.half_play": 7e-6},
        },
        "draws": {"n": 0, "note": "not run yet: make scenario NAME=liu_vs_ols_draws"},
        "regime": {"note": "not run yet: make scenario NAME=liu_regime"},
    }


def test_the_effects_named_are_the_truths():
    s = summary()
    text = report(s)
    assert "lost motion" in text and "thermal growth" in text and "lead error" in text
    s["truth_effects"] = ["joint_backlash"]
    text = report(s)
    assert "lost motion" in text
    assert "thermal" not in text.split("## Does")[1].split("## Can")[0]
    assert "lead error" not in text
    s["truth_effects"] = []
    text = report(s)
    assert "no effect beyond geometry" in text and "lost motion" not in text


def test_the_loop_sentence_follows_the_loop():
    s = summary()
    assert "The loop row shows what does lower the error here: naming the effect (backlash)" in (
        report(s)
    )
    s["loop"]["coefficients"] = {}  # named nothing, and worse than OLS
    s["loop"]["diagnosed_effect"] = "none"
    s["layers"]["test"]["loop"] = _row(0.0400, 0.11)
    text = report(s)
    assert "what does lower the error" not in text
    assert "The loop named no effect (none)" in text and "no better than OLS" in text
    s["loop"]["coefficients"] = {"backlash.theta4.half_play": 1e-4}  # named, and worse
    s["loop"]["diagnosed_effect"] = "backlash"
    text = report(s)
    assert "The loop named backlash, but modelling it does not lower" in text


def test_the_verdict_on_the_papers_gain_follows_the_numbers():
    s = summary()
    text = report(s)
    assert "**No**" in text and "+0.56 %" in text  # 0.0359 -> 0.0361 mm
    s["layers"]["test"]["liu_paper_deg"] = _row(0.0300, 0.060)  # the paper's gain
    text = report(s)
    assert "**Yes**" in text and "-16.43 %" in text


def test_the_noise_ceiling_and_eta_are_the_runs():
    s = summary()
    text = report(s)
    assert "1.92 um mean and 4.65 um max" in text and "less than the paper's gain" in text
    assert "| liu (HKB k) | 37.3 | 6.4 |" in text
    assert "eta is about the parameters, not the pose error" in text
    assert "its shrinkage takes 0.33 um of noise off the mean" in text
    s["noise_only_test_um"]["ols"] = {"mean": 7.5, "max": 20.0}
    s["noise_only_test_um"]["liu_paper_deg"] = {"mean": 9.5, "max": 25.0}
    s["eta_at_used_d_percent"]["liu"] = 21.0
    text = report(s)
    assert "7.5 um mean and 20 um max" in text and "as much as the paper's gain" in text
    assert "2 um more than OLS's" in text
    assert "| liu (HKB k) | 37.3 | 21.0 |" in text


def test_the_order_control_verdict_follows_the_control():
    s = summary()
    assert "within round-off: the order" in report(s)
    s["scoring"]["order_control_um"] = 1.2
    text = report(s)
    assert "NOT within round-off" in text and "1.2 um" in text


def test_liu_is_named_by_its_k_and_the_header_agrees_with_the_log():
    """The header prints d and k as the run's log does (d = 4.966e-12, k = 5.506e-12), and
    the HKB variant is never called the paper's Liu."""
    text = report(summary())
    assert "d = 4.966e-12, k = 5.506e-12 (d/k = 0.902)" in text
    assert "| liu (HKB k) |" in text and "| liu_paper_deg (paper's Liu) |" in text
    assert "| liu | " not in text


def test_the_regime_pointer_reads_the_map():
    s = summary()
    assert "make scenario NAME=liu_regime" in report(s)
    cell = {
        "n_draws": 20,
        "estimators": {
            "liu_paper_deg": {"minus_ols_um": {"median": 0.07}, "better_fraction": 0.15},
            "liu": {"minus_ols_um": {"median": -0.4}, "better_fraction": 1.0},
        },
    }
    s["regime"] = {
        "source": "liu_regime/summary.json",
        "cells": {"interpolated/0.005": cell},
        "sigmas_mm": [0.005],
        "truth_effects": ["joint_backlash"],
    }
    text = report(s)
    assert "With the lost motion of the joints (backlash), the paper's Liu minus OLS" in text
    assert "+0.07 um (median), better in 15% of draws" in text
    cell["estimators"]["liu_paper_deg"]["minus_ols_max_um"] = {"median": 4.2}
    assert "better in 15% of draws; in the test maximum +4.2 um." in report(s)
    del cell["estimators"]["liu_paper_deg"]["minus_ols_max_um"]
    assert "test layer by tracker noise (median, and the share of draws it is better): " in text
    assert "0.005 mm: +0.07 um (15%)." in text
    assert "geometry-only" not in text
    geo = copy.deepcopy(cell)
    geo["estimators"]["liu_paper_deg"] = {"minus_ols_um": {"median": -1.5}, "better_fraction": 0.98}
    s["regime_geometry"] = {
        "source": "liu_regime_geometry/summary.json",
        "cells": {"interpolated/0.02": geo},
        "sigmas_mm": [0.02],
    }
    text = report(s)
    assert "On a geometry-only truth (liu_regime_geometry/summary.json)" in text
    assert "0.02 mm: -1.5 um (98%)." in text
    assert "The HKB Liu (`liu`) gains most in interpolated/0.005, 0.4 um" in text
    assert "The paper's Liu (`liu_paper_deg`) gains over OLS in no cell" in text


@pytest.fixture
def regime_summary() -> dict:
    def cell(ols: float, paper: float, better: float) -> dict:
        e = {"minus_ols_um": {"median": paper, "p05": paper - 1, "p95": paper + 1}}
        return {
            "n_draws": 20,
            "ols_test_pos_mean_um": {"median": ols},
            "estimators": {"liu_paper_deg": {**e, "better_fraction": better}},
        }

    return {
        "truth_random": None,
        "truth_effects": [],
        "n_draws": 20,
        "seeds": [0, 19],
        "engine": "local",
        "runtime_s": 10.0,
        "placement_poses": {"interpolated": {"description": "the middle layer", "n_poses": 49}},
        "scoring": {"order_control_um": 0.0},
        "estimators": ["liu_paper_deg"],
        "cells": {
            "interpolated/0.005": cell(36.0, 0.07, 0.15),
            "interpolated/0.05": cell(41.0, -2.0, 0.95),
        },
    }


def test_the_regime_report_says_where_each_estimator_wins(regime_summary):
    text = regime_report(regime_summary)
    assert (
        "the paper's estimator minus OLS in the test mean is +0.07 um (median; better in 15%"
        in text
    )
    assert "in 1 of 2 cells: interpolated/0.05." in text
    assert "The lowest median is -2 um (4.9% of OLS's 41 um there)" in text
    regime_summary["cells"]["interpolated/0.005"]["estimators"]["liu_paper_deg"] = {
        "minus_ols_um": {"median": -0.5, "p05": -1, "p95": 0},
        "better_fraction": 0.97,
    }
    text = regime_report(regime_summary)
    assert (
        "the paper's estimator minus OLS in the test mean is -0.5 um (median; better in 97%" in text
    )
    assert "in 2 of 2 cells" in text


def test_the_regime_tables_give_the_maximum_and_one_sign(regime_summary):
    """The test maximum beside the mean (the paper's Liu gain was in the maximum; a mean that
    wins can come with a maximum that loses), and the heat maps' numbers are the tables'
    (estimator minus OLS, below 0 better)."""
    import numpy as np

    from scenarios.studies.liu_regime.figures import cell_text, minus_ols_grid

    cell = regime_summary["cells"]["interpolated/0.05"]
    cell["ols_test_pos_max_um"] = {"median": 97.0}
    e = cell["estimators"]["liu_paper_deg"]
    e["minus_ols_max_um"] = {"median": 5.5, "p05": 3.0, "p95": 8.0}
    e["better_fraction_max"] = 0.1
    text = regime_report(regime_summary)
    assert "| interpolated/0.05 | 41 | 97 | -2 (-3..-1), 95% | +5.5 (+3..+8), 10% |" in text
    assert "| interpolated/0.005 | 36 | n/a | +0.07 (-0.93..+1.07), 15% | n/a |" in text
    assert "(better in 95% of draws); in the test maximum +5.5 um (better in 10%)." in text
    assert "One sign everywhere, tables, sentences and heat maps: estimator minus OLS" in text
    # the paper's Table 5: 35 -> 30 um in the mean, 92 -> 56 um in the maximum
    assert "(the paper's Liu: -14.3% in the mean, -39.1% in the maximum)" in text
    regime_summary.update(placements=["interpolated"], sigmas_mm=[0.005, 0.05])
    diff, better = minus_ols_grid(regime_summary, "liu_paper_deg")
    # noise down, placements across, in mm (every figure's unit)
    np.testing.assert_allclose(diff, [[0.07e-3], [-2.0e-3]], rtol=1e-12)
    assert better.tolist() == [[0.15], [0.95]]
    assert cell_text(-2.0e-3, 0.95) == "-0.0020\n95% better"


def test_the_bias_sentence_follows_the_noise_free_cells(regime_summary):
    """ "Shrinkage does not remove such a bias" only where the noise-free cells (sigma 0) show
    no estimator better than OLS; where one is (the paper's Liu gained 3.4 um in the tilted
    cell at sigma 0), the sentence says the bias moved."""
    from scenarios.studies.liu_vs_ols.sentences import bias_clause

    def free(diff: float, better: float) -> dict:
        e = {"minus_ols_um": {"median": diff, "p05": diff - 1, "p95": diff + 1}}
        return {
            "n_draws": 20,
            "ols_test_pos_mean_um": {"median": 30.0},
            "estimators": {"liu_paper_deg": {**e, "better_fraction": better}},
        }

    assert "no noise-free cell" in bias_clause({})
    reg = {"cells": {"tilted/0": free(-3.4, 0.9), "tilted/0.005": free(1.0, 0.2)}}
    said = bias_clause(reg)
    assert said.startswith("shrinking the estimate can move such a bias")
    assert "`liu_paper_deg` minus OLS -3.4 um in tilted (median; better in 90% of draws)" in said
    reg["cells"]["tilted/0"] = free(0.8, 0.1)
    said = bias_clause(reg)
    assert said.startswith("shrinking the estimate does not remove such a bias")
    assert "(lowest: `liu_paper_deg` minus OLS +0.8 um in tilted" in said
    s = summary()
    s["regime"] = {"source": "liu_regime/summary.json", "sigmas_mm": [0.0], **reg}
    assert "describes; shrinking the estimate does not remove such a bias: noise-free" in report(s)
    regime_summary["cells"]["tilted/0"] = free(-3.4, 0.9)
    text = regime_report(regime_summary)
    assert "Noise-free (sigma 0), where shrinkage has no noise to take off" in text
    assert "`liu_paper_deg (paper's Liu)` in tilted -3.4 um (90% better): what shrinkage" in text
    del regime_summary["cells"]["tilted/0"]
    assert "Noise-free" not in regime_report(regime_summary)


def test_a_residual_within_the_noise_after_the_refit_is_no_effect():
    """The diagnosis reads the one-step fine OLS; when it modelled nothing and the nonlinear
    refit passes the chi-square noise test (p >= 0.01, the diagnosis's own level), the loop
    says "none" (the geometry-only control once said "unexplained" at 0.0085 mm against a
    floor of 0.0087 mm); below the level, or with an effect modelled, the diagnosis's word."""
    from scenarios.studies.liu_vs_ols.loop import NOISE_ALPHA, chi_square_p, loop_verdict

    assert NOISE_ALPHA == 0.01
    chosen, why = loop_verdict("unexplained", "it exceeds", False, 0.353, 0.0085, 0.0087)
    assert chosen == "none"
    assert "leaves 0.0085 mm against the noise floor 0.0087 mm" in why
    assert "chi-square p = 0.353 >= 0.01" in why
    assert loop_verdict("unexplained", "it exceeds", False, 0.009, 0.0095, 0.0087) == (
        "unexplained",
        "it exceeds",
    )
    assert loop_verdict("backlash", "lowers", True, 0.5, 0.0086, 0.0087) == ("backlash", "lowers")
    assert loop_verdict("none", "noise", False, 0.5, 0.0086, 0.0087) == ("none", "noise")
    # chi-square: a sum of squares at its expectation (dof sigma^2) for many dof is p ~ 0.5;
    # 20 % above it with dof = 1000 is 4.47 standard deviations (sqrt(2 dof) = 44.7): a normal
    # tail of 4e-6, the chi-square's right tail heavier but below 1e-4
    assert chi_square_p(1000 * 0.005**2, 0.005, 1000) == pytest.approx(0.494, abs=0.003)
    assert 4e-6 < chi_square_p(1200 * 0.005**2, 0.005, 1000) < 1e-4


def test_the_files_loop_sentence_says_nothing_was_named():
    """diagnose naming "none" leaves identify --with nothing to add: no "the loop did not
    close", and the geometric fit's test RMS from the files."""
    from scenarios.files_loop import files_loop_sentence

    f = {
        "exit_codes": {"diagnose": 0, "identify": 2, "verify": None},
        "failed_because": {"identify": "error: it named no effect (none)"},
        "named_effect": "none",
        "test_rms_mm": {"geometric_fit": 0.0071, "diagnosis": 0.0071, "with_effect": None},
        "files": "loop_through_files",
    }
    text = files_loop_sentence(f)
    assert "diagnose named no effect (none), so identify --with has nothing to add" in text
    assert "says so (exit 2); the geometric fit's test RMS is 0.0071 mm" in text
    assert "did not close" not in text
    f["named_effect"], f["exit_codes"]["diagnose"] = None, 2
    assert "the loop did not close" in files_loop_sentence(f)
