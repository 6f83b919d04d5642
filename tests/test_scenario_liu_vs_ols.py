"""CI accuracy gates of the main scenario (issue: liu_vs_ols) and its summary contract."""

from __future__ import annotations

import pytest

from scenarios.runner import run_scenario


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    s, out_dir = run_scenario("liu_vs_ols", tmp_path_factory.mktemp("results"), quiet=True)
    assert (out_dir / "summary.json").is_file() and (out_dir / "report.md").is_file()
    for name in s["figures"].values():
        assert (out_dir / name).stat().st_size > 1000
    return s


@pytest.mark.accuracy
def test_summary_contract(summary):
    for key in (
        "n_source_errors",
        "n_identifiable",
        "coarse_iterations",
        "liu_d",
        "eta_percent",
        "runtime_s",
    ):
        assert key in summary
    for group in ("calibration", "test"):
        for stage in ("coarse", "ols", "liu"):
            for q in ("pos_max_mm", "pos_mean_mm", "ori_max_deg", "ori_mean_deg"):
                assert summary["layers"][group][stage][q] >= 0.0
    assert summary["n_source_errors"] == 150
    assert summary["n_identifiable"] == 51
    assert 0.0 <= summary["liu_d"] <= 1.0  # d / k: 0 is ridge, 1 is OLS
    assert summary["liu_k"] > 0.0


@pytest.mark.accuracy
def test_coarse_calibration_converges(summary):
    assert summary["coarse_converged"]
    assert summary["coarse_relative_changes"][-1] <= 0.05


@pytest.mark.accuracy
def test_liu_no_worse_than_ols_in_the_test_layer(summary):
    test = summary["layers"]["test"]
    assert test["liu"]["pos_mean_mm"] <= test["ols"]["pos_mean_mm"]


@pytest.mark.accuracy
def test_fine_calibration_lowers_the_max_error_in_every_layer(summary):
    for group in ("calibration", "test"):
        stages = summary["layers"][group]
        for est in ("ols", "liu"):
            assert stages[est]["pos_max_mm"] < stages["coarse"]["pos_max_mm"]


@pytest.mark.accuracy
def test_liu_is_more_robust_than_ols(summary):
    assert summary["eta_percent"] > 0.0
    assert summary["monte_carlo_runs"] == 10000
