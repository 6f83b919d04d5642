"""Coarse then fine calibration of the hybrid polisher, Liu against OLS (first paper, 4-5).

Truth: every source error of the polisher drawn at random (seeded), and the effects of
``truth.effects`` (the scenario file states and justifies their magnitudes). The calibration
side sees only the nominal model, the error model and tracker readings of the gauge targets:
1. coarse: encoder offsets by OLS on the middle layer (5 x 5 nodes), iterated (Eq. 15);
2. fine: the identifiable set (Steps 1-3) from the upper and lower layers (7 x 7 nodes each)
   by OLS, Liu (Eqs. 11-14), ridge and PCR;
3. the loop (scenarios.studies.liu_vs_ols.loop): residual diagnosis after the fine OLS, the named
   effect added to the model, full nonlinear refit, compensation by fixed-point inversion;
4. compensation of the NC poses by the predicted pose error twist (Eq. 16), re-measured on
   the truth twin at every node of the calibration layers and of the test (middle) layer,
   every stage on the same machine state (scenarios.studies.liu_vs_ols.pipeline.score), with an
   "OLS again" control scored last;
5. Monte Carlo of the fine estimate (Eqs. 17-18) over noise draws sharing one H, eta at the
   d the run used, and the test-layer error the noise alone leaves
   (scenarios.studies.liu_vs_ols.noise).

A scenario with a ``[draws]`` table is the draw study instead (scenarios.studies.liu_vs_ols.draws).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.analysis import orientation_reach
from calib.compensate import TwistCompensation
from scenarios.config import Scenario
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.studies.liu_vs_ols.combinations import PlanReading, plan_readings, sentence
from scenarios.studies.liu_vs_ols.loop import close_loop, close_loop_through_files
from scenarios.studies.liu_vs_ols.noise import display_scale, eta_at_used, monte_carlo
from scenarios.studies.liu_vs_ols.pipeline import (
    CONTROL,
    PAPER,
    PAPER_ROW_OF,
    calibrate,
    make_bench,
    order_control_um,
    paper_match,
    score,
    stage_commands,
    with_control,
)
from scenarios.studies.liu_vs_ols.recording import record
from scenarios.studies.liu_vs_ols.sentences import estimator_parameters
from twin.kinematics import one_blas_thread
from twin.parameters import KINDS, ParameterSet

# Tolerances of the paper match (ours / paper, on all three layers as Table 5 reports them):
# the rows that do not depend on the estimator, coarse and OLS, position max and mean.
REGIME_STUDY = "liu_regime"  # the regime map, beside this scenario's results when run
REGIME_GEOMETRY = "liu_regime_geometry"  # the same map on a geometry-only truth


def orientation_check(
    twists: np.ndarray, params: ParameterSet, layers: dict[str, dict[str, dict[str, float]]]
) -> dict[str, Any]:
    """Can the orientation rows come from the machine? Each source error's rotation of the
    head per millimetre it moves P (the controller's model at the test layer's poses), beside
    the orientation / position ratio of each row, ours and the paper's (all three layers)."""
    reach = orientation_reach(
        twists, list(params.names), params.kind == KINDS.index("joint_zero")
    ).as_dict()
    rows = {}
    for stage, paper in PAPER["table5"].items():
        ours = layers["all"].get(PAPER_ROW_OF[stage])
        rows[stage] = {
            "paper_max_deg_per_mm": paper["ori_max_deg"] / paper["pos_max_mm"],
            "paper_mean_deg_per_mm": paper["ori_mean_deg"] / paper["pos_mean_mm"],
            "ours_max_deg_per_mm": None
            if ours is None
            else ours["ori_max_deg"] / ours["pos_max_mm"],
            "ours_mean_deg_per_mm": (
                None if ours is None else ours["ori_mean_deg"] / ours["pos_mean_mm"]
            ),
        }
    return {**reach, "rows": rows}


DRAW_STUDY = "liu_vs_ols_draws"  # its results beside this scenario's, under the same root


def draws_reference(out_dir: Path) -> dict[str, Any]:
    """The draw study's numbers when it has been run into the same results root."""
    path = out_dir.parent / DRAW_STUDY / "summary.json"
    if not path.is_file():
        return {"n": 0, "note": f"not run yet: make scenario NAME={DRAW_STUDY}"}
    d = json.loads(path.read_text()).get("draws", {})
    d = {k: v for k, v in d.items() if k != "groups"}
    return {**d, "source": f"{DRAW_STUDY}/summary.json"}


def regime_reference(out_dir: Path, name: str = REGIME_STUDY) -> dict[str, Any]:
    """The regime map's cells when it has been run into the same results root."""
    path = out_dir.parent / name / "summary.json"
    if not path.is_file():
        return {"note": f"not run yet: make scenario NAME={name}"}
    r = json.loads(path.read_text())
    return {
        "source": f"{name}/summary.json",
        "cells": r.get("cells", {}),
        "sigmas_mm": r.get("sigmas_mm"),
        "placements": r.get("placements"),
        "truth_effects": r.get("truth_effects", []),
    }


def run(
    scenario: Scenario,
    out_dir: Path,
    progress: Progress,
    recorder: Recorder,
    figures: bool = True,
) -> dict[str, Any]:
    """The study; ``figures=False`` leaves out the PNG figures (the summary's numbers are the
    same; its ``figures`` table is then empty)."""
    if isinstance(scenario.data.get("draws"), dict):
        from scenarios.studies.liu_vs_ols.draws import run_draws

        return run_draws(scenario, out_dir, progress, recorder)
    t_start = time.perf_counter()
    bench = make_bench(scenario)
    nominal, params = bench.machine.nominal, bench.machine.params
    cal = calibrate(bench, scenario.get("fine.estimators", list), progress)
    problem, estimates = cal.problem, cal.estimates
    for m, (est, _) in estimates.items():
        said = [estimator_parameters(est.bias_parameter, est.scale_parameter), *est.notes]
        said = [t for t in said if t]
        progress.note(f"{m}: {'; '.join(said)}" if said else m)

    progress.step("loop: residual diagnosis, the named effect in the model, nonlinear refit")
    t_loop = time.perf_counter()
    loop = close_loop(bench, cal, scenario.get("loop.estimator", str, "ols"))
    progress.note(
        f"{loop.verdict()[0]}: residual {loop.residual_rms_before_mm:.4g} -> "
        f"{loop.residual_rms_after_mm:.4g} mm (3D RMS per reading; noise floor "
        f"{loop.noise_floor_rms_mm:.4g} mm), {time.perf_counter() - t_loop:.1f} s"
    )

    progress.step("compensation (Eq. 16; the loop's fixed point) and re-measurement")
    score_nodes = scenario.get(
        "scoring.nodes_per_side", int, scenario.get("fine.nodes_per_side", int)
    )
    poses = {g: bench.poses(g, score_nodes) for g in ("calibration", "test")}
    comps = {
        g: TwistCompensation.prepare(bench.model, cal.coarse.values, p) for g, p in poses.items()
    }
    cmds: dict[str, dict[str, Any]] = {}
    for group, p in poses.items():
        cmds[group] = stage_commands(bench, cal, p, comp=comps[group])
        near = (comps[group].qpos, comps[group].actuator_jacobians)
        cmds[group]["loop"] = lambda order, p=p, near=near: loop.commands(bench, p, order, near)
        cmds[group] = with_control(cmds[group])  # "OLS again", scored last
    scoring_start = bench.clock[0]
    with one_blas_thread():
        layers, maps = score(bench, poses, cmds)  # every stage from the same clock

    maps = {g: {k: v for k, v in st.items() if k != CONTROL} for g, st in maps.items()}
    kept_names = [params.names[k] for k in problem.columns]
    shown = display_scale(params, problem.columns)
    record(
        recorder,
        nominal,
        maps,
        estimates,
        kept_names,
        shown,
        cal.coarse.relative_changes,
        loop,
    )

    progress.step("Monte Carlo of the fine estimate (Eqs. 17-18)")
    runs = scenario.get("monte_carlo.runs", int)
    test_b = comps["test"].twist_jacobians[:, :3, problem.columns]
    with one_blas_thread():  # 10^4 x 294 by 294 x 51 at most: one thread is as fast
        noise = monte_carlo(bench, cal, runs, test_b)
    progress.counter("runs", runs, runs)
    spread = noise.spread
    sigma_ols, sigma_liu = spread["ols"], spread["liu"]
    eta_used = eta_at_used(estimates, display_scale(params, problem.columns), bench.sigma_m)

    progress.step("the loop through the files: diagnose --out, identify --with, verify")
    through = close_loop_through_files(bench, cal, cmds["test"]["coarse"], out_dir)
    progress.note(f"exit codes {through['exit_codes']}, {through['runtime_s']:.1f} s")

    liu_est = estimates.get("liu", (None,))[0]
    control_um = order_control_um(layers)
    summary: dict[str, Any] = {
        "scenario": scenario.name,
        "model": nominal.name,
        "n_source_errors": len(params),
        "n_identifiable": int(problem.columns.size),
        "coarse_iterations": cal.coarse.iterations,
        "coarse_converged": cal.coarse.converged,
        "coarse_relative_changes": cal.coarse.relative_changes,
        # d / k: 0 is ridge with Liu's k, 1 is OLS (the paper's d, whose k is 1)
        "liu_d": liu_est.bias_parameter / liu_est.scale_parameter if liu_est is not None else None,
        "liu_k": liu_est.scale_parameter if liu_est is not None else None,
        "liu_bias_d": liu_est.bias_parameter if liu_est is not None else None,  # d itself
        "liu_notes": list(liu_est.notes) if liu_est is not None else [],
        "eta_percent": noise.eta_percent("liu"),
        "eta_percent_liu_k1": noise.eta_percent("liu_k1"),
        # eta with d and k fixed at the values this run chose (analytic; Eq. 17 for each)
        "eta_at_used_d_percent": eta_used,
        # the test-layer pose error the tracker noise alone leaves after each estimator (um;
        # mean over the Monte Carlo runs of the test layer's mean and max): OLS's is the
        # ceiling of any shrinkage gain
        "noise_only_test_um": {
            label: {"mean": noise.test_mean_um[label], "max": noise.test_max_um[label]}
            for label in noise.spread
        },
        "scoring": {
            "clock": "same",
            "start_pose": scoring_start,
            "order_control_um": control_um,
            "order_control_all_um": order_control_um(layers, "all"),
            "note": "every stage of every layer measured from the same clock (the same "
            "thermal state); 'ols_again' is OLS's commands scored after every other stage",
        },
        "tracker_sigma_mm": bench.sigma_m * 1e3,
        "truth_effects": [e.name for e in bench.effects],
        "truth_random": scenario.section("truth").get("random"),
        "paper_units": {
            "note": "the paper's Eq. 11 literally (k = 1) on H in mm and deg; mm and rad beside",
            "sigma2": "RSS / n (Eq. 13)",
            "eta_percent": noise.eta_percent("liu_paper_deg"),
            "eta_percent_rad": noise.eta_percent("liu_paper_rad"),
            "layers": {
                group: {"liu": stages.get("liu_paper_deg"), "liu_rad": stages.get("liu_paper_rad")}
                for group, stages in layers.items()
            },
        },
        "monte_carlo_runs": runs,
        "sigma_ols": sigma_ols,
        "sigma_liu": sigma_liu,
        "layers": layers,
        "paper_match": paper_match(layers),
        "orientation_reach": orientation_check(comps["test"].twist_jacobians, params, layers),
        "loop": loop.summary(),
        "loop_through_files": through,
        "draws": draws_reference(out_dir),
        "regime": regime_reference(out_dir),
        "regime_geometry": regime_reference(out_dir, REGIME_GEOMETRY),
        "estimators": {
            m: {
                "bias_parameter": e.bias_parameter,
                "scale_parameter": e.scale_parameter,
                "notes": list(e.notes),
            }
            for m, (e, _) in estimates.items()
        },
        "identifiable": kept_names,
        "paper": PAPER,
    }
    labels = [label for label in ("ols", "liu") if label in estimates]
    readings = plan_readings(bench, cal, labels)
    # what the fine plan's readings fix of each estimate, and what they cannot
    summary["plan_combinations"] = {label: r.summary for label, r in readings.items()}
    summary["figures"] = {}
    if figures:
        summary["figures"] = _write_figures(out_dir, maps, readings)
        maps_png = out_dir / summary["figures"]["error_maps_position"]
        recorder.log_figure("error_maps", maps_png, "error maps: every stage, every layer")
    summary["runtime_s"] = time.perf_counter() - t_start
    recorder.log_report(scenario.study, summary)
    return summary


def _write_figures(
    out_dir: Path, maps: dict[str, dict[str, Any]], readings: dict[str, PlanReading]
) -> dict[str, str]:
    """The error maps and, for OLS and Liu, the estimates beside what the plan reads of them
    (matplotlib imported here)."""
    from scenarios.figures import collection_paused
    from scenarios.studies.liu_vs_ols.combinations_figure import combinations_png
    from scenarios.studies.liu_vs_ols.figures import write_figures

    with collection_paused():
        written = write_figures(out_dir, maps)
        for label, r in readings.items():
            combinations_png(
                out_dir / f"estimates_{label}.png",
                f"polisher, {label}",
                r.combinations,
                r.estimate,
                r.std,
                r.truth,
                sentence(r.summary),
            )
    written.update({f"estimates_{label}": f"estimates_{label}.png" for label in readings})
    return written
