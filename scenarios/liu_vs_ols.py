"""Coarse then fine calibration of the hybrid polisher, Liu against OLS (first paper, 4-5).

Truth: every source error of the polisher drawn at random (seeded), and the effects of
``truth.effects`` (the scenario file states and justifies their magnitudes). The calibration
side sees only the nominal model, the error model and tracker readings of the gauge targets:
1. coarse: encoder offsets by OLS on the middle layer (5 x 5 nodes), iterated (Eq. 15);
2. fine: the identifiable set (Steps 1-3) from the upper and lower layers (7 x 7 nodes each)
   by OLS, Liu (Eqs. 11-14), ridge and PCR;
3. the loop (scenarios.liu_vs_ols_loop): residual diagnosis after the fine OLS, the named
   effect added to the model, full nonlinear refit, compensation by fixed-point inversion;
4. compensation of the NC poses by the predicted pose error twist (Eq. 16), re-measured on
   the truth twin at every node of the calibration layers and of the test (middle) layer;
5. Monte Carlo of the fine estimate (Eqs. 17-18) over noise draws sharing one H.

A scenario with a ``[draws]`` table is the draw study instead (scenarios.liu_vs_ols_draws).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.compensation import TwistCompensation
from calib.estimators.linear import DrawEstimator, draws
from calib.estimators.liu import Liu
from calib.estimators.liu_paper_units import LiuPaperUnits
from calib.estimators.ols import OLS
from calib.nominal_targets import nominal_targets
from calib.orientation_reach import orientation_reach
from scenarios.config import Scenario
from scenarios.liu_vs_ols_loop import close_loop
from scenarios.liu_vs_ols_pipeline import (
    PAPER,
    Bench,
    Calibration,
    calibrate,
    make_bench,
    score,
    stage_commands,
)
from scenarios.liu_vs_ols_recording import record
from scenarios.progress import Progress
from scenarios.recording import Recorder
from twin.kinematics_batch import forward_batch
from twin.kinematics_fast import one_blas_thread
from twin.parameters import KINDS, ParameterSet

# Tolerances of the paper match (ours / paper, on all three layers as Table 5 reports them):
# the rows that do not depend on the estimator, coarse and OLS, position max and mean.
POSITION_FACTOR = 1.5
MATCHED_ROWS = ("coarse", "ols")
MC_CHUNK = 2000  # Monte Carlo runs projected at once


def paper_match(layers: dict[str, dict[str, dict[str, float]]]) -> dict[str, Any]:
    """Ours / paper for every number of the coarse, OLS and Liu rows (all three layers)."""
    out: dict[str, Any] = {"position_factor": POSITION_FACTOR, "rows": {}}
    for stage, paper in PAPER["table5"].items():
        ours = layers["all"].get(stage)
        if ours is None:
            continue
        ratios = {q: ours[q] / v for q, v in paper.items()}
        within = all(
            1.0 / POSITION_FACTOR <= ratios[q] <= POSITION_FACTOR
            for q in ("pos_max_mm", "pos_mean_mm")
        )
        out["rows"][stage] = {"ratio": ratios, "position_within": within}
    out["position_reproduced"] = all(
        out["rows"][s]["position_within"] for s in MATCHED_ROWS if s in out["rows"]
    )
    return out


def _monte_carlo(bench: Bench, cal: Calibration, runs: int, progress: Progress) -> dict:
    """Eqs. 17-18: the spread of each estimator over noise draws on one truth and one H.

    As the paper's simulation (section 5): the targets of the truth's geometry at the fine
    plan (its effects left out: the simulation studies the measurement disturbance alone),
    plus 10^4 draws of the tracker noise."""
    params, problem = bench.machine.params, cal.problem
    coarse_mech = bench.model.mechanism(cal.coarse.values)
    commands = cal.fine_commands  # the fine plan's commands at the coarse settings
    clean = forward_batch(bench.machine.truth, commands).targets
    dp_clean = (clean - nominal_targets(coarse_mech, cal.fine_poses)).reshape(-1)
    noise = bench.rng.normal(0.0, bench.sigma_m, size=(runs, dp_clean.size))
    shown = params.to_display(np.eye(len(params)))[np.ix_(problem.columns, problem.columns)]
    scale = np.diag(shown)  # SI -> mm/deg per kept parameter
    estimators: dict[str, DrawEstimator] = {
        "ols": OLS(),
        "liu": Liu(),
        "liu_k1": Liu(k=1.0),
        "liu_paper_deg": LiuPaperUnits(angle_unit="deg", is_angle=problem.is_angle),
        "liu_paper_rad": LiuPaperUnits(angle_unit="rad", is_angle=problem.is_angle),
    }
    # each run's estimate is its own; what the estimators share of a run (its products with
    # the singular vectors of H, its OLS residual) is computed once, MC_CHUNK runs at a time
    shared = draws(problem.h, dp_clean, noise, MC_CHUNK)
    out = {label: est.fit_draws(shared) * scale for label, est in estimators.items()}
    progress.counter("runs", runs, runs)
    return {label: float(np.sqrt(np.sum(d.var(axis=0, ddof=1)))) for label, d in out.items()}


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
        ours = layers["all"].get(stage)
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
        from scenarios.liu_vs_ols_draws import run_draws

        return run_draws(scenario, out_dir, progress, recorder)
    t_start = time.perf_counter()
    bench = make_bench(scenario)
    nominal, params = bench.machine.nominal, bench.machine.params
    cal = calibrate(bench, scenario.get("fine.estimators", list), progress)
    problem, estimates = cal.problem, cal.estimates
    for m, (est, _) in estimates.items():
        extra = f", {est.bias_parameter:.4g}" if est.bias_parameter is not None else ""
        progress.note(f"{m}{extra}{'; ' + '; '.join(est.notes) if est.notes else ''}")

    progress.step("loop: residual diagnosis, the named effect in the model, nonlinear refit")
    t_loop = time.perf_counter()
    loop = close_loop(bench, cal, scenario.get("loop.estimator", str, "ols"))
    progress.note(
        f"{loop.diagnosis.chosen}: residual {loop.residual_rms_before_mm:.4g} -> "
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
    with one_blas_thread():
        layers, maps = score(bench, poses, cmds)

    kept_names = [params.names[k] for k in problem.columns]
    shown = np.diag(
        params.to_display(np.eye(len(params)))[np.ix_(problem.columns, problem.columns)]
    )
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
    with one_blas_thread():  # 10^4 x 294 by 294 x 51 at most: one thread is as fast
        spread = _monte_carlo(bench, cal, runs, progress)
    sigma_ols, sigma_liu = spread["ols"], spread["liu"]

    liu_est = estimates.get("liu", (None,))[0]
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
        "liu_notes": list(liu_est.notes) if liu_est is not None else [],
        "eta_percent": (1.0 - sigma_liu / sigma_ols) * 100.0,
        "eta_percent_liu_k1": (1.0 - spread["liu_k1"] / sigma_ols) * 100.0,
        "truth_effects": [e.name for e in bench.effects],
        "truth_random": scenario.section("truth").get("random"),
        "paper_units": {
            "note": "the paper's Eq. 11 literally (k = 1) on H in mm and deg; mm and rad beside",
            "eta_percent": (1.0 - spread["liu_paper_deg"] / sigma_ols) * 100.0,
            "eta_percent_rad": (1.0 - spread["liu_paper_rad"] / sigma_ols) * 100.0,
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
        "draws": draws_reference(out_dir),
        "estimators": {
            m: {"bias_parameter": e.bias_parameter, "notes": list(e.notes)}
            for m, (e, _) in estimates.items()
        },
        "identifiable": kept_names,
        "paper": PAPER,
    }
    summary["figures"] = {}
    if figures:
        summary["figures"] = _write_figures(out_dir, maps, estimates, kept_names, shown)
        maps_png = out_dir / summary["figures"]["error_maps_position"]
        recorder.log_figure("error_maps", maps_png, "error maps: every stage, every layer")
    summary["runtime_s"] = time.perf_counter() - t_start
    recorder.log_report(scenario.study, summary)
    return summary


def _write_figures(
    out_dir: Path,
    maps: dict[str, dict[str, Any]],
    estimates: dict[str, tuple[Any, np.ndarray]],
    kept_names: list[str],
    shown: np.ndarray,
) -> dict[str, str]:
    """The error maps and the parameter bar charts of OLS and Liu (matplotlib imported here)."""
    from scenarios.figures import Bars, collection_paused, parameter_bars_pngs
    from scenarios.liu_vs_ols_figures import write_figures

    labels = [label for label in ("ols", "liu") if label in estimates]
    charts = [
        Bars(
            out_dir / f"estimates_{label}.png",
            f"polisher: {label} estimates of the identifiable set (mm, deg)",
            estimates[label][0].x * shown,
            estimates[label][0].std_errors * shown,
        )
        for label in labels
    ]
    with collection_paused():
        written = write_figures(out_dir, maps)
        parameter_bars_pngs(kept_names, charts)  # one figure, the names drawn once
    written.update({f"estimates_{label}": f"estimates_{label}.png" for label in labels})
    return written
