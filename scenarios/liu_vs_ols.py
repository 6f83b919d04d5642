"""Coarse then fine calibration of the hybrid polisher, Liu against OLS (first paper, 4-5).

Truth: every source error of the polisher drawn at random (seeded). The calibration side
sees only the nominal model, the error model and tracker readings of the gauge targets:
1. coarse: encoder offsets by OLS on the middle layer (5 x 5 nodes), iterated (Eq. 15);
2. fine: the identifiable set (Steps 1-3) from the upper and lower layers (7 x 7 nodes each)
   by OLS, Liu (Eqs. 11-14), ridge and PCR;
3. compensation of the NC poses by the predicted pose error twist (Eq. 16), re-measured on
   the truth twin at every node of the calibration layers and of the test (middle) layer;
4. Monte Carlo of the fine estimate (Eqs. 17-18) over noise draws sharing one H.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.coarse import coarse_calibration
from calib.compensation import twist_compensated_commands
from calib.estimators.registry import make_estimator
from calib.fine import estimate, fine_problem
from calib.scoring import max_mean_stats, pose_errors
from scenarios.config import Scenario
from scenarios.figures import parameter_bars_png
from scenarios.machine_setup import build_effects, load_machine
from scenarios.progress import Progress
from scenarios.recording import Recorder
from twin.kinematics_batch import forward_batch
from twin.measurement import measure as twin_measure
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import commands_for_poses, layer_poses

# First paper, Table 5 (experiment) and section 5 (simulation).
PAPER = {
    "table5": {
        "coarse": {
            "pos_max_mm": 0.166,
            "pos_mean_mm": 0.083,
            "ori_max_deg": 0.206,
            "ori_mean_deg": 0.073,
        },
        "ols": {
            "pos_max_mm": 0.092,
            "pos_mean_mm": 0.035,
            "ori_max_deg": 0.091,
            "ori_mean_deg": 0.046,
        },
        "liu": {
            "pos_max_mm": 0.056,
            "pos_mean_mm": 0.030,
            "ori_max_deg": 0.051,
            "ori_mean_deg": 0.037,
        },
    },
    "eta_percent": 63.9,
    "n_source_errors": 145,
    "n_identifiable": 54,
}


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t_start = time.perf_counter()
    rng = np.random.default_rng(scenario.get("seed", int))
    machine = load_machine(scenario, rng)
    nominal, params, truth = machine.nominal, machine.params, machine.truth
    model = machine.calibration_model()
    encoder = np.array([n.endswith(".encoder") for n in params.names])
    sigma = scenario.get("tracker.sigma_mm", float) * 1e-3
    tracker = Tracker(
        position_m=tuple(v * 1e-3 for v in scenario.get("tracker.position_mm", list)),
        noise=TrackerNoise("gaussian", sigma, 0.0),
        repeats=scenario.get("tracker.repeats", int, 1),
    )

    effects = build_effects(scenario)
    clock = [0]  # poses measured so far: the measurement sequence the effects follow

    def run_machine(commands: np.ndarray):
        """The truth twin with its effects, at the next poses of the sequence."""
        order = clock[0] + np.arange(len(commands))
        clock[0] += len(commands)
        return twin_measure(truth, commands, tracker, rng, effects=effects, order=order)

    def measure(commands: np.ndarray) -> np.ndarray:
        """The machine as the calibration sees it: commands in, tracker readings out."""
        if not effects:  # geometry only: the twin's direct path
            return tracker.measure_averaged(forward_batch(truth, commands).targets, rng)
        return run_machine(commands).readings.mean(axis=2)

    def true_targets(commands: np.ndarray) -> np.ndarray:
        """Where the targets really are (no tracker noise), for scoring."""
        if not effects:
            return forward_batch(truth, commands).targets
        return run_machine(commands).true_targets

    half = tuple(v * 1e-3 for v in scenario.get("workspace.half_width_mm", list))
    z_layers = {k: v * 1e-3 for k, v in scenario.section("layers").items()}
    coarse_nodes = scenario.get("coarse.nodes_per_side", int)
    fine_nodes = scenario.get("fine.nodes_per_side", int)
    score_nodes = scenario.get("scoring.nodes_per_side", int, fine_nodes)

    progress.step(f"coarse calibration: middle layer, {coarse_nodes} x {coarse_nodes} nodes")
    coarse = coarse_calibration(
        model,
        encoder,
        layer_poses(nominal, [z_layers["middle"]], coarse_nodes, half),
        measure,
        rel_tol=scenario.get("coarse.rel_tol", float, 0.05),
    )
    progress.note(
        f"{coarse.iterations} rounds, relative changes "
        + ", ".join(f"{c:.3g}" for c in coarse.relative_changes)
    )

    progress.step(f"fine calibration: upper and lower layers, {fine_nodes} x {fine_nodes} nodes")
    fine_poses = layer_poses(nominal, [z_layers["upper"], z_layers["lower"]], fine_nodes, half)
    problem = fine_problem(model, coarse.values, encoder, fine_poses, measure)
    estimates = {}
    for entry in scenario.get("fine.estimators", list):
        # "ols", or a table {label = "liu_k1", method = "liu", k = 1.0} with options
        if isinstance(entry, str):
            estimates[entry] = estimate(problem, entry)
        else:
            opts = {k: v for k, v in entry.items() if k not in ("label", "method")}
            estimates[entry["label"]] = estimate(problem, entry["method"], **opts)
    for m, (est, _) in estimates.items():
        extra = f", {est.bias_parameter:.4g}" if est.bias_parameter is not None else ""
        progress.note(f"{m}{extra}{'; ' + '; '.join(est.notes) if est.notes else ''}")

    progress.step("compensation (Eq. 16) and re-measurement at every node")
    layer_sets = {
        "calibration": [z_layers["upper"], z_layers["lower"]],
        "test": [z_layers["middle"]],
    }
    layers: dict[str, dict[str, dict[str, float]]] = {}
    maps: dict[str, dict[str, Any]] = {}
    coarse_mech = model.mechanism(coarse.values)
    for group, heights in layer_sets.items():
        poses = layer_poses(nominal, heights, score_nodes, half)
        stage_cmds = {
            "uncalibrated": commands_for_poses(nominal, poses),  # before any calibration
            "coarse": commands_for_poses(coarse_mech, poses),
        }
        for m, (est, _) in estimates.items():
            stage_cmds[m] = twist_compensated_commands(
                model, coarse.values, est.x, problem.columns, poses
            )
        layers[group] = {}
        for stage, cmds in stage_cmds.items():
            true = true_targets(cmds)
            errs = pose_errors(poses, true, nominal.target_local())
            layers[group][stage] = max_mean_stats(errs)
            maps.setdefault(group, {})[stage] = (poses, errs)

    recorder.log_mechanism(nominal)
    for stage in [s for s in ("coarse", "ols", "liu") if s in stage_cmds]:  # the test layer
        recorder.log_pose_set("test_node", truth, stage_cmds[stage], poses, f"test layer, {stage}")
    for group, stages in maps.items():
        for stage, (poses, errs) in stages.items():
            # each stage on its own colour scale: the uncalibrated 20 mm would leave every
            # calibrated map uniformly dark (the scale is in the view's title)
            vmax = float(np.max(errs.position)) * 1e3
            recorder.log_error_map(stage, group, poses[:, :3], errs.position * 1e3, vmax)
    kept_names = [params.names[k] for k in problem.columns]
    for label, (est, _) in estimates.items():
        shown = params.to_display(np.eye(len(params)))[np.ix_(problem.columns, problem.columns)]
        recorder.log_parameters(
            label, kept_names, est.x * np.diag(shown), est.std_errors * np.diag(shown)
        )
    for k, change in enumerate(coarse.relative_changes):
        recorder.log_metric("coarse_relative_change", "coarse_round", k + 1, change)
    progress.step("Monte Carlo of the fine estimate (Eqs. 17-18)")
    runs = scenario.get("monte_carlo.runs", int)
    clean = true_targets(commands_for_poses(coarse_mech, fine_poses))
    from calib.nominal_targets import nominal_targets

    dp_clean = (clean - nominal_targets(coarse_mech, fine_poses)).reshape(-1)
    noise = rng.normal(0.0, sigma, size=(runs, dp_clean.size))
    shown = params.to_display(np.eye(len(params)))[np.ix_(problem.columns, problem.columns)]
    scale = np.diag(shown)  # SI -> mm/deg per kept parameter
    spread = {}
    for label, est in (
        ("ols", make_estimator("ols")),
        ("liu", make_estimator("liu")),
        ("liu_k1", make_estimator("liu", k=1.0)),
        ("liu_paper_deg", make_estimator("liu_paper", angle_unit="deg", is_angle=problem.is_angle)),
        ("liu_paper_rad", make_estimator("liu_paper", angle_unit="rad", is_angle=problem.is_angle)),
    ):
        draws = est.fit_many(problem.h, dp_clean[None, :] + noise) * scale
        spread[label] = float(np.sqrt(np.sum(draws.var(axis=0, ddof=1))))
        progress.counter("estimators", len(spread), 5)
    sigma_ols, sigma_liu = spread["ols"], spread["liu"]
    eta = (1.0 - sigma_liu / sigma_ols) * 100.0

    liu_est = estimates.get("liu", (None,))[0]
    summary: dict[str, Any] = {
        "scenario": scenario.name,
        "model": nominal.name,
        "n_source_errors": len(params),
        "n_identifiable": int(problem.columns.size),
        "coarse_iterations": coarse.iterations,
        "coarse_converged": coarse.converged,
        "coarse_relative_changes": coarse.relative_changes,
        # d / k: 0 is ridge with Liu's k, 1 is OLS (the paper's d, whose k is 1)
        "liu_d": liu_est.bias_parameter / liu_est.scale_parameter if liu_est is not None else None,
        "liu_k": liu_est.scale_parameter if liu_est is not None else None,
        "liu_notes": list(liu_est.notes) if liu_est is not None else [],
        "eta_percent": eta,
        "eta_percent_liu_k1": (1.0 - spread["liu_k1"] / sigma_ols) * 100.0,
        "truth_effects": [e.name for e in effects],
        "paper_units": {
            "note": "the paper's Eq. 11 literally (k = 1) on H in mm and deg; mm and rad beside",
            "eta_percent": (1.0 - spread["liu_paper_deg"] / sigma_ols) * 100.0,
            "eta_percent_rad": (1.0 - spread["liu_paper_rad"] / sigma_ols) * 100.0,
            "layers": {
                group: {
                    "liu": stages.get("liu_paper_deg"),
                    "liu_rad": stages.get("liu_paper_rad"),
                }
                for group, stages in layers.items()
            },
        },
        "monte_carlo_runs": runs,
        "sigma_ols": sigma_ols,
        "sigma_liu": sigma_liu,
        "layers": layers,
        "estimators": {
            m: {"bias_parameter": e.bias_parameter, "notes": list(e.notes)}
            for m, (e, _) in estimates.items()
        },
        "identifiable": [params.names[k] for k in problem.columns],
        "paper": PAPER,
    }
    from scenarios.liu_vs_ols_figures import write_figures

    summary["figures"] = write_figures(out_dir, maps)
    for label in ("ols", "liu"):
        if label in estimates:
            est = estimates[label][0]
            shown = np.diag(
                params.to_display(np.eye(len(params)))[np.ix_(problem.columns, problem.columns)]
            )
            parameter_bars_png(
                out_dir / f"estimates_{label}.png",
                f"polisher: {label} estimates of the identifiable set (mm, deg)",
                [params.names[k] for k in problem.columns],
                est.x * shown,
                est.std_errors * shown,
            )
            summary["figures"][f"estimates_{label}"] = f"estimates_{label}.png"
    summary["runtime_s"] = time.perf_counter() - t_start
    recorder.log_report(scenario.study, summary)
    return summary
