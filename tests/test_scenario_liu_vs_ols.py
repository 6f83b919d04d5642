"""CI accuracy gates of the main scenario (issue: liu_vs_ols) and its summary contract.

The scenario's truth is the paper's experiment regime
(scenarios/studies/liu_vs_ols/liu_vs_ols.toml): the rows
that do not depend on the estimator, coarse and OLS, must come out as the paper's Table 5
(position max and mean within the factor the scenario states, all three layers): a
property of the truth chosen for the scenario, disclosed in its TOML; the Liu row is the
prediction, judged against the noise ceiling of the same run; and the
loop (diagnosis, the named effect modelled, refit, compensation) below the OLS row.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from recording_faces import assert_every_face_has_data

from calib.estimators.liu_cv import LiuCV, _folds
from calib.estimators.ols import OLS
from scenarios.config import load_scenario
from scenarios.runner import run_scenario
from scenarios.studies.liu_vs_ols.draws import aggregate
from scenarios.studies.liu_vs_ols.pipeline import PAPER, POSITION_FACTOR, paper_match

STATS = ("pos_max_mm", "pos_mean_mm", "ori_max_deg", "ori_mean_deg")


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    s, out_dir = run_scenario("liu_vs_ols", tmp_path_factory.mktemp("results"), quiet=True)
    assert (out_dir / "summary.json").is_file() and (out_dir / "report.md").is_file()
    for name in s["figures"].values():
        assert (out_dir / name).stat().st_size > 1000
    # the recording: every view has data on its timeline; the loop has a view of its own
    # (the diagnosis figure) and a machine view, beside OLS's and Liu's
    views = {v["name"] for v in assert_every_face_has_data(out_dir / "liu_vs_ols.rrd")}
    assert f"loop: {s['loop']['diagnosed_effect']}" in views
    assert {"loop, test layer", "ols, test layer"} <= {n.split(":")[0] for n in views}
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
        "truth_effects",
    ):
        assert key in summary
    for group in ("calibration", "test", "all"):
        for stage in ("uncalibrated", "coarse", "ols", "liu", "liu_paper_deg", "loop"):
            for q in STATS:
                assert summary["layers"][group][stage][q] >= 0.0
    assert summary["truth_effects"] == ["joint_backlash", "thermal_growth", "lead_error"]
    assert summary["n_source_errors"] == 150
    assert summary["n_identifiable"] == 51
    assert 0.0 <= summary["liu_d"] <= 1.0  # d / k: 0 is ridge, 1 is OLS
    assert summary["liu_k"] > 0.0
    assert np.isfinite(summary["paper_units"]["eta_percent"])
    assert summary["paper_units"]["layers"]["test"]["liu"]["pos_mean_mm"] > 0.0
    loop = summary["loop"]
    for key in ("diagnosed_effect", "residual_rms_before_mm", "residual_rms_after_mm"):
        assert key in loop
    assert "n" in summary["draws"]
    # the paper's Liu uses Eq. 13's sigma^2 = RSS / n
    assert summary["estimators"]["liu_paper_deg"]["scale_parameter"] == 1.0
    assert "sigma^2 = RSS / n (Eq. 13)" in summary["estimators"]["liu_paper_deg"]["notes"]


@pytest.mark.accuracy
def test_stages_are_scored_on_one_machine_state(summary):
    """The "OLS again" control, scored after every other stage on a truth whose limbs warm
    with every pose, equals OLS to round-off (issue: measurement order decided the winner)."""
    assert abs(summary["scoring"]["order_control_um"]) < 0.05
    assert abs(summary["scoring"]["order_control_all_um"]) < 0.05
    for group in ("calibration", "test", "all"):
        assert summary["layers"][group]["ols_again"] == pytest.approx(
            summary["layers"][group]["ols"], abs=5e-5
        )


@pytest.mark.accuracy
def test_noise_ceiling_and_eta_at_the_d_used(summary):
    """The noise alone leaves OLS a few um on the test layer (the ceiling of any shrinkage
    gain, below the paper's 5 um gain in the mean); eta at the d the run used is reported
    beside the Monte Carlo's, for every Liu variant."""
    ceiling = summary["noise_only_test_um"]["ols"]
    assert 0.5 < ceiling["mean"] < 5.0 and ceiling["mean"] < ceiling["max"] < 15.0
    assert ceiling["mean"] < 0.2 * summary["layers"]["test"]["ols"]["pos_mean_mm"] * 1e3
    for label in ("liu", "liu_k1", "liu_paper_deg", "liu_paper_rad"):
        eta = summary["eta_at_used_d_percent"][label]
        assert 0.0 <= eta < 100.0  # 0 <= d <= k: never more spread than OLS


@pytest.mark.accuracy
def test_uncalibrated_row_is_the_raw_machine(summary):
    # encoder offsets of 3 mm and 0.1 deg: the uncalibrated head is off by millimetres
    for group in ("calibration", "test"):
        assert summary["layers"][group]["uncalibrated"]["pos_mean_mm"] > 1.0


@pytest.mark.accuracy
def test_coarse_and_ols_rows_match_the_paper(summary):
    """Table 5, all three layers: coarse 0.166 / 0.083 mm, OLS 0.092 / 0.035 mm (max / mean).

    This is a calibration of the scenario, not a finding: its truth (the sizes of the random
    structural errors and of the three effects) was chosen so that these two rows, which do
    not depend on the estimator, come out as the paper measured them (disclosed in
    liu_vs_ols.toml, checked there on seeds 2018, 1 and 2). The gate keeps the chosen truth
    from drifting away from the paper's regime; the Liu row below is the prediction."""
    ours = summary["layers"]["all"]
    for stage in ("coarse", "ols"):
        for q in ("pos_max_mm", "pos_mean_mm"):
            ratio = ours[stage][q] / PAPER["table5"][stage][q]
            assert 1.0 / POSITION_FACTOR <= ratio <= POSITION_FACTOR, (stage, q, ratio)
    assert summary["paper_match"]["position_reproduced"]


@pytest.mark.accuracy
def test_liu_prediction_is_ols_within_the_noise_ceiling(summary):
    """The prediction, on the truth chosen for the coarse and OLS rows: Liu (HKB k) does not
    reproduce the paper's gain on the test layer (0.030 against OLS's 0.035 mm, 14 %).

    The bound is the noise ceiling of the same run: the test-layer mean position error the
    tracker noise alone leaves after OLS (its Monte Carlo over 10^4 draws). A shrinkage
    estimator gains by scattering less under the noise, and removing all of the noise's part
    of each pose's error lowers the mean by at most the mean of that part (triangle
    inequality): Liu's gain over OLS cannot exceed the ceiling, and the prediction is that it
    stays within the ceiling of OLS on either side. The paper's 5 um gain is above it."""
    test = summary["layers"]["test"]
    ceiling_mm = summary["noise_only_test_um"]["ols"]["mean"] * 1e-3
    diff = test["liu"]["pos_mean_mm"] - test["ols"]["pos_mean_mm"]
    assert abs(diff) < ceiling_mm, (diff, ceiling_mm)
    paper = PAPER["table5"]
    assert paper["ols"]["pos_mean_mm"] - paper["liu"]["pos_mean_mm"] > ceiling_mm


@pytest.mark.accuracy
def test_loop_row_below_ols_on_the_test_layer(summary):
    test = summary["layers"]["test"]
    assert test["loop"]["pos_mean_mm"] < 0.8 * test["ols"]["pos_mean_mm"]
    assert test["loop"]["pos_max_mm"] < test["ols"]["pos_max_mm"]


@pytest.mark.accuracy
def test_loop_names_the_lost_motion_and_lowers_the_residual(summary):
    loop = summary["loop"]
    assert "backlash" in loop["diagnosed_effect"]
    assert loop["lm_converged"]
    before, after = loop["residual_rms_before_mm"], loop["residual_rms_after_mm"]
    assert after < 0.5 * before
    # not below what the tracker noise alone leaves (3D RMS per reading, sqrt(3) sigma)
    assert loop["noise_floor_rms_mm"] == pytest.approx(np.sqrt(3.0) * 0.005, rel=1e-12)
    assert after > 0.8 * loop["noise_floor_rms_mm"]
    # the wrist's half play found near its size (0.25 mrad play: 0.125 mrad half play)
    for j in ("theta4", "theta5", "theta6"):
        assert 0.5e-4 < loop["coefficients"][f"backlash.{j}.half_play"] < 2.5e-4


@pytest.mark.accuracy
def test_orientation_rows_out_of_the_machines_reach(summary):
    """Why the orientation rows are not gated: every source error turns the head by less, per
    millimetre it moves P, than the paper's rows show (about 1 deg/mm); the twin's rows stay
    within the reach of its source errors."""
    r = summary["orientation_reach"]
    paper = [v for row in r["rows"].values() for k, v in row.items() if k.startswith("paper")]
    assert r["largest_median_deg_per_mm"] < 0.5 * min(paper)
    assert r["largest_joint_motion"] == "limb4.j4.encoder"  # the wrist axis nearest P
    # an actuated UPS limb turns the platform about the base: a lever of metres (1/r)
    limb = r["joint_motions"]["limb1.j3.encoder"]["median_deg_per_mm"]
    assert 1.5e3 < np.degrees(1.0) / limb < 2.5e3
    for stage in ("coarse", "ols"):
        assert r["rows"][stage]["ours_mean_deg_per_mm"] < r["largest_median_deg_per_mm"]


@pytest.mark.accuracy
def test_coarse_calibration_converges(summary):
    assert summary["coarse_converged"]
    assert summary["coarse_relative_changes"][-1] <= 0.05


@pytest.mark.accuracy
def test_fine_calibration_lowers_the_max_error_in_every_layer(summary):
    for group in ("calibration", "test"):
        stages = summary["layers"][group]
        for est in ("ols", "liu"):
            assert stages[est]["pos_max_mm"] < stages["coarse"]["pos_max_mm"]


def test_paper_match_ratios():
    rows = {s: dict(v) for s, v in PAPER["table5"].items()}
    m = paper_match({"all": rows})
    assert m["position_reproduced"]
    assert m["rows"]["ols"]["ratio"]["pos_mean_mm"] == pytest.approx(1.0)
    rows["coarse"]["pos_max_mm"] = PAPER["table5"]["coarse"]["pos_max_mm"] * 1.6
    assert not paper_match({"all": rows})["position_reproduced"]


def test_the_other_scenarios_of_the_study_load():
    geo = load_scenario("liu_vs_ols_geometry")
    assert geo.study == "liu_vs_ols" and not geo.data["truth"].get("effects")
    assert geo.data["truth"]["random"]["translation_mm"] == 1.0
    draws = load_scenario("liu_vs_ols_draws")
    assert draws.study == "liu_vs_ols" and draws.data["draws"]["n"] >= 100
    assert "liu_cv" in draws.data["draws"]["estimators"]


def test_draw_aggregate_differences_and_fractions():
    def row(mean, mx):
        return {"pos_mean_mm": mean, "pos_max_mm": mx}

    results = []
    for i in range(20):
        ols = row(0.04, 0.10)
        liu = row(0.04 + (i - 4.5) * 1e-3, 0.10 - 1e-3)  # better in 5 of 20 draws
        lay = {"coarse": row(0.1, 0.2), "ols": ols, "liu": liu}
        results.append({"layers": {g: lay for g in ("calibration", "test", "all")}})
    agg = aggregate(results, ["liu"])
    liu = agg["groups"]["test"]["liu"]
    assert agg["n"] == 20
    assert liu["better_fraction"] == pytest.approx(5 / 20)
    assert liu["better_fraction_max"] == 1.0
    assert liu["minus_ols_pos_mean_mm"]["median"] == pytest.approx(5e-3, abs=1e-12)
    assert liu["minus_ols_pos_max_mm"]["p05"] == pytest.approx(-1e-3, abs=1e-12)


def test_liu_cv_is_ols_on_noise_free_data():
    rng = np.random.default_rng(3)
    h = rng.normal(size=(90, 6))
    y = h @ rng.normal(size=6)
    est = LiuCV(folds=5).fit(h, y)
    np.testing.assert_allclose(est.x, OLS().fit(h, y).x, rtol=1e-9, atol=1e-12)
    assert est.bias_parameter == pytest.approx(est.scale_parameter)  # d = k: OLS


def test_liu_cv_shrinks_a_collinear_noisy_problem():
    rng = np.random.default_rng(5)
    base = rng.normal(size=(180, 1))
    h = np.hstack([base + 1e-3 * rng.normal(size=(180, 1)), base, rng.normal(size=(180, 2))])
    b_true = np.array([1.0, 1.0, 0.5, -0.5])
    y = h @ b_true + 0.5 * rng.normal(size=180)
    est = LiuCV(folds=6).fit(h, y)
    ols = OLS().fit(h, y)
    assert est.bias_parameter < est.scale_parameter  # d < k: shrinks
    assert np.linalg.norm(est.x - b_true) < np.linalg.norm(ols.x - b_true)


def test_liu_cv_folds_keep_poses_whole():
    labels = _folds(9 * 10, 9, 5)
    assert np.all(labels.reshape(10, 9) == labels.reshape(10, 9)[:, :1])
    assert sorted(set(labels.tolist())) == [0, 1, 2, 3, 4]
    with pytest.raises(ValueError, match="whole poses"):
        _folds(10, 9, 2)


def test_draw_study_records_the_distribution_of_liu_minus_ols(tmp_path):
    """Two draws in this process: the report's figure (estimator - OLS over the draws) is a
    view of the recording, and every view has data."""
    root = Path(__file__).resolve().parent.parent
    text = (root / "scenarios" / "studies" / "liu_vs_ols" / "liu_vs_ols_draws.toml").read_text()
    for old, new in (("n = 100", "n = 2"), ('engine = "ray"', 'engine = "local"')):
        assert old in text, old
        text = text.replace(old, new)
    draws = text.index("[draws]")  # two estimators of the draws' list: seconds, not a minute
    text = text[:draws] + re.sub(
        r"estimators = \[.*?\]\n",
        'estimators = ["ols", "liu"]\n',
        text[draws:],
        count=1,
        flags=re.S,
    )
    path = tmp_path / "liu_vs_ols_draws.toml"
    path.write_text(text)
    s, out = run_scenario(str(path), tmp_path / "results", quiet=True)
    assert s["draws"]["n"] == 2 and (out / "draws_liu_minus_ols.png").stat().st_size > 1000
    views = assert_every_face_has_data(out / "liu_vs_ols_draws.rrd")
    assert {v["name"] for v in views} == {
        "estimator minus OLS over the draws",
        "report: key numbers",
    }


def test_the_geometry_only_control_names_no_effect(tmp_path):
    """A truth without an effect: the diagnosis of the one-step fine OLS sees its
    linearisation, the nonlinear refit leaves the noise, and the loop says "none" (the
    report as well); the refitted residual passes the noise test it is judged by."""
    s, out = run_scenario("liu_vs_ols_geometry", tmp_path, quiet=True, record=False, figures=False)
    lp = s["loop"]
    assert lp["diagnosed_effect"] == "none" and not lp["modelled"], lp["reason"]
    assert lp["refit_chi2_p_value"] >= 0.01
    assert lp["residual_rms_after_mm"] < 1.05 * lp["noise_floor_rms_mm"]
    assert "Diagnosed effect: **none**" in (out / "report.md").read_text()
