"""Where the Liu estimator beats OLS: liu_vs_ols's plan and twin over tracker noise and test
placement.

A grid of cells, tracker noise sigma (``regime.sigmas_mm``) by test placement
(``regime.placements``):

* ``interpolated``: the middle layer between the two calibration layers (the paper's test);
* ``extrapolated``: a layer ``extrapolated_offset_mm`` outside the calibration layers (below
  the lower one by default), its nodes whose nominal commands come within
  ``stroke_margin_mm`` of a stroke end left out (the compensated commands must stay inside);
* ``tilted``: the middle layer's nodes with the head tilted by ``tilt_deg`` (5-10 deg) about a
  horizontal axis through P of random direction (drawn once, from ``tilt_seed``).

Each draw (a task on the sweep engine: Ray locally, or the cluster RAY_ADDRESS names) is one
truth (seed ``seed + i``) at one sigma: the coarse and fine calibration of liu_vs_ols by
every estimator of ``fine.estimators``, then every placement compensated by each estimate
(Eq. 16) and re-measured on the truth, every stage from the same clock (the same machine
state) with the "OLS again" control last. A draw's truth and noise normals are the same at
every sigma (its seed draws both; the noise is sigma times the same normals), so the cells
differ by the noise level and the placement only. Per cell: the estimator's test-layer mean
position error minus OLS's (um), its median and 5-95 % range over the draws, and the fraction
of draws where it is below OLS.
"""

from __future__ import annotations

import copy
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.compensate import TwistCompensation
from scenarios.config import PLACEMENTS, Scenario, load_scenario
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.studies.liu_vs_ols.pipeline import (
    CONTROL,
    Bench,
    calibrate,
    estimator_label,
    make_bench,
    score,
    with_control,
)
from scenarios.sweep.draws import map_draws
from scenarios.sweep.engine import ENV_ENGINE, engine_env
from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics import inverse, one_blas_thread
from twin.rotations import matrix_from_rotvec, rpy_from_matrix
from twin.workspace import layer_poses

DEFAULTS = {
    "extrapolated_offset_mm": 60.0,
    "extrapolated_side": "below",
    "stroke_margin_mm": 10.0,
    "tilt_deg": [5.0, 10.0],
    "tilt_seed": 0,
}


def cell_key(placement: str, sigma_mm: float) -> str:
    """``"interpolated/0.005"``: the placement and sigma in mm as written (``%g``)."""
    return f"{placement}/{sigma_mm:g}"


def _setting(scenario: Scenario, key: str) -> Any:
    kind = {list: list, str: str, int: int}.get(type(DEFAULTS[key]), float)
    return scenario.get(f"regime.{key}", kind, DEFAULTS[key])


def reachable(bench: Bench, poses: np.ndarray, margin_m: float) -> np.ndarray:
    """Which poses the nominal inverse kinematics reaches with every prismatic command at
    least ``margin_m`` inside its stroke (revolute ones inside their range)."""
    mech = bench.machine.nominal
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    margin = np.where(mech.actuator_is_slide, margin_m, 0.0)
    ok = np.zeros(len(poses), dtype=bool)
    q = None
    for i, pose in enumerate(poses):
        try:
            sol = inverse(mech, pose, start=q, check_stroke=False)
        except (WorkspaceError, ClosureError):
            continue
        c = sol.actuators
        ok[i] = bool(np.all((c >= lo + margin) & (c <= hi - margin)))
        if ok[i]:
            q = sol.qpos
    return ok


def tilted(poses: np.ndarray, tilt_deg: list[float], seed: int) -> np.ndarray:
    """``poses`` with the head turned about P by an angle uniform in ``tilt_deg`` about a
    horizontal axis of uniform direction (one draw per pose, from ``seed``)."""
    rng = np.random.default_rng(seed)
    angle = np.radians(rng.uniform(tilt_deg[0], tilt_deg[1], len(poses)))
    azimuth = rng.uniform(0.0, 2.0 * np.pi, len(poses))
    axes = np.stack([np.cos(azimuth), np.sin(azimuth), np.zeros(len(poses))], axis=1)
    out = np.array(poses, dtype=float)
    out[:, 3:] = rpy_from_matrix(matrix_from_rotvec(axes * angle[:, None]))
    return out


def placement_poses(scenario: Scenario, nodes: int) -> dict[str, dict[str, Any]]:
    """The test poses of each placement (the same for every draw) and what they are."""
    bench = make_bench(scenario)
    z = bench.z_layers
    out: dict[str, dict[str, Any]] = {}
    for placement in scenario.get("regime.placements", list):
        if placement == "interpolated":
            poses = bench.poses("test", nodes)
            what = f"the middle layer, z = {z['middle'] * 1e3:+.0f} mm"
        elif placement == "extrapolated":
            offset = _setting(scenario, "extrapolated_offset_mm") * 1e-3
            below = _setting(scenario, "extrapolated_side") == "below"
            height = min(z["upper"], z["lower"]) - offset if below else max(z.values()) + offset
            grid = layer_poses(bench.machine.nominal, [height], nodes, bench.half)
            margin = _setting(scenario, "stroke_margin_mm") * 1e-3
            poses = grid[reachable(bench, grid, margin)]
            what = (
                f"a layer {offset * 1e3:.0f} mm {'below' if below else 'above'} the calibration "
                f"layers, z = {height * 1e3:+.0f} mm ({len(poses)} of {len(grid)} nodes: "
                f"the others' commands come within {margin * 1e3:g} mm of a stroke end)"
            )
        else:
            lo, hi = _setting(scenario, "tilt_deg")
            poses = tilted(bench.poses("test", nodes), [lo, hi], _setting(scenario, "tilt_seed"))
            what = f"the middle layer's nodes, the head tilted {lo:g}-{hi:g} deg about P"
        if not len(poses):
            raise WorkspaceError(f"the {placement} placement has no reachable test pose")
        out[placement] = {"poses": poses, "description": what}
    return out


def draw_scenario(path: str, seed: int, sigma_mm: float) -> Scenario:
    """The study's scenario as one draw: its own seed and tracker sigma."""
    base = load_scenario(path)
    data = copy.deepcopy(base.data)
    data["seed"] = int(seed)
    data["tracker"]["sigma_mm"] = float(sigma_mm)
    return Scenario(base.name, base.study, base.path, data, base.schema)


def regime_task(
    path: str, seed: int, sigma_mm: float, poses: dict[str, np.ndarray]
) -> dict[str, Any]:
    """One truth at one sigma, every placement: plain data out."""
    scenario = draw_scenario(path, seed, sigma_mm)
    bench = make_bench(scenario)
    cal = calibrate(bench, scenario.get("fine.estimators", list))
    cmds = {}
    with one_blas_thread():
        for placement, p in poses.items():
            comp = TwistCompensation.prepare(bench.model, cal.coarse.values, p)
            stages = {
                m: comp.commands(est.x, cal.problem.columns)
                for m, (est, _) in cal.estimates.items()
            }
            cmds[placement] = with_control(stages)
        layers, _ = score(bench, poses, cmds)  # every stage from the same clock
    keep = ("pos_mean_mm", "pos_max_mm")
    return {
        "seed": int(seed),
        "sigma_mm": float(sigma_mm),
        "layers": {
            g: {st: {q: v[q] for q in keep} for st, v in s.items()} for g, s in layers.items()
        },
        "estimators": {
            m: {"d": e.bias_parameter, "k": e.scale_parameter}
            for m, (e, _) in cal.estimates.items()
        },
    }


def _spread(values: np.ndarray) -> dict[str, float]:
    p05, med, p95 = np.percentile(values, [5.0, 50.0, 95.0])
    return {"median": float(med), "p05": float(p05), "p95": float(p95)}


def aggregate_cells(
    results: list[dict[str, Any]], placements: list[str], sigmas: list[float], labels: list[str]
) -> dict[str, Any]:
    """``cells["<placement>/<sigma>"]``: n_draws, OLS's test mean and max (um), the control,
    and per estimator minus_ols_um {median, p05, p95} and better_fraction of the test mean,
    minus_ols_max_um and better_fraction_max of the test maximum (estimator minus OLS)."""
    cells: dict[str, Any] = {}
    for placement in placements:
        for sigma in sigmas:
            rows = [r["layers"][placement] for r in results if r["sigma_mm"] == sigma]
            ols = np.array([r["ols"]["pos_mean_mm"] for r in rows]) * 1e3
            ols_max = np.array([r["ols"]["pos_max_mm"] for r in rows]) * 1e3
            control = np.array([r[CONTROL]["pos_mean_mm"] for r in rows]) * 1e3 - ols
            cell: dict[str, Any] = {
                "n_draws": len(rows),
                "ols_test_pos_mean_um": _spread(ols),
                "ols_test_pos_max_um": _spread(ols_max),
                "order_control_um": float(np.max(np.abs(control))),
                "estimators": {},
            }
            for label in labels:
                diff = np.array([r[label]["pos_mean_mm"] for r in rows]) * 1e3 - ols
                diff_max = np.array([r[label]["pos_max_mm"] for r in rows]) * 1e3 - ols_max
                cell["estimators"][label] = {
                    "minus_ols_um": _spread(diff),
                    "better_fraction": float(np.mean(diff < 0.0)),
                    "minus_ols_max_um": _spread(diff_max),
                    "better_fraction_max": float(np.mean(diff_max < 0.0)),
                }
            cells[cell_key(placement, sigma)] = cell
    return cells


def _parameters(results: list[dict[str, Any]], sigmas: list[float]) -> dict[str, Any]:
    """Median d and k of each Liu variant at each sigma (how much it chose to shrink)."""
    out: dict[str, Any] = {}
    for sigma in sigmas:
        rows = [r["estimators"] for r in results if r["sigma_mm"] == sigma]
        block = {}
        for label, v in rows[0].items():
            if v["k"] is None:
                continue
            d = np.array([r[label]["d"] for r in rows])
            k = np.array([r[label]["k"] for r in rows])
            block[label] = {
                "d_median": float(np.median(d)),
                "k_median": float(np.median(k)),
                "d_over_k_median": float(np.median(d / k)),
            }
        out[f"{sigma:g}"] = block
    return out


def run(
    scenario: Scenario,
    out_dir: Path,
    progress: Progress,
    recorder: Recorder,
    figures: bool = True,
) -> dict[str, Any]:
    t0 = time.perf_counter()
    sigmas = [float(v) for v in scenario.get("regime.sigmas_mm", list)]
    placements = [p for p in PLACEMENTS if p in scenario.get("regime.placements", list)]
    n = scenario.get("regime.draws", int)
    labels = [estimator_label(e) for e in scenario.get("fine.estimators", list)]
    if "ols" not in labels:
        raise ValueError("the regime map compares with OLS: put 'ols' in fine.estimators")
    others = [lab for lab in labels if lab != "ols"]
    nodes = scenario.get("scoring.nodes_per_side", int, scenario.get("fine.nodes_per_side", int))
    seed0 = scenario.get("seed", int)
    test = placement_poses(scenario, nodes)
    poses = {p: test[p]["poses"] for p in placements}
    args = [(str(scenario.path), seed0 + i, s, poses) for s in sigmas for i in range(n)]
    engine = os.environ.get(ENV_ENGINE) or scenario.get("regime.engine", str, "ray")
    progress.step(
        f"{len(sigmas)} noise levels x {n} truth draws (seeds {seed0}..{seed0 + n - 1}), "
        f"{len(placements)} placements each, on the {engine} engine"
    )
    with engine_env(engine):
        results = map_draws(regime_task, args, progress, "cells' draws")
    cells = aggregate_cells(results, placements, sigmas, others)
    summary: dict[str, Any] = {
        "scenario": scenario.name,
        "study": "liu_regime",
        "truth_random": scenario.section("truth").get("random"),
        "truth_effects": [e.get("kind") for e in scenario.get("truth.effects", list, [])],
        "sigmas_mm": sigmas,
        "placements": placements,
        "placement_poses": {
            p: {"n_poses": len(poses[p]), "description": test[p]["description"]} for p in placements
        },
        "n_draws": n,
        "seeds": [seed0, seed0 + n - 1],
        "estimators": others,
        "engine": engine,
        "cells": cells,
        "estimator_parameters": _parameters(results, sigmas),
        "scoring": {
            "clock": "same",
            # the largest |OLS again - OLS| of any draw in any cell, test mean, um
            "order_control_um": max(c["order_control_um"] for c in cells.values()),
        },
    }
    summary["figures"] = {}
    if figures:
        from scenarios.studies.liu_regime.figures import heat_maps

        summary["figures"] = heat_maps(out_dir, summary)
        for name, file in summary["figures"].items():
            recorder.log_image(name, out_dir / file)
    summary["runtime_s"] = time.perf_counter() - t0
    recorder.log_report(scenario.study, summary)
    return summary
