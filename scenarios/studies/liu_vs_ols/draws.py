"""The draw study: liu_vs_ols over many truth draws, each estimator minus OLS.

Each draw is the whole pipeline on its own truth (``seed + i``: structural errors and encoder
offsets from [truth.random], the same effects, fresh tracker noise): coarse, fine by every
estimator of ``draws.estimators`` (the paper's Liu ``liu_paper_deg``, the Liu-type estimator
with the HKB k ``liu``, ridge, PCR, the cross-validated Liu), compensation and
re-measurement of the calibration and test layers, every stage on the same machine state
with the "OLS again" control scored last (scenarios.studies.liu_vs_ols.pipeline.score). The draws
are sweep tasks (scenarios.sweep.draws.map_draws) on Ray (a local instance sized to the
machine, or the cluster RAY_ADDRESS names) or in this process (``draws.engine``, or
``PKM_ENGINE``). Reported per layer group: median and 5-95 % range of (estimator - OLS) in
the mean and the max position error, and the fraction of draws where the estimator is below
OLS.
"""

from __future__ import annotations

import copy
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.config import Scenario, load_scenario
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.studies.liu_vs_ols.pipeline import (
    CONTROL,
    PAPER,
    POSITION_FACTOR,
    calibrate,
    estimator_label,
    make_bench,
    paper_match,
    score,
    stage_commands,
    with_control,
)
from scenarios.sweep.draws import map_draws
from scenarios.sweep.engine import ENV_ENGINE, engine_env
from scenarios.sweep.runner import ProgressBar

GROUPS = ("calibration", "test", "all")
QUANTITIES = ("pos_mean_mm", "pos_max_mm")


def draw_scenario(path: str, seed: int) -> Scenario:
    """The study's scenario as one draw: its own seed, no [draws] table."""
    base = load_scenario(path)
    data = copy.deepcopy(base.data)
    data["seed"] = int(seed)
    data.pop("draws", None)
    return Scenario(base.name, base.study, base.path, data, base.schema)


def draw_task(path: str, seed: int, entries: list, nodes: int) -> dict[str, Any]:
    """One truth draw, plain data out: the stats of every stage per layer group."""
    bench = make_bench(draw_scenario(path, seed))
    cal = calibrate(bench, entries)
    poses = {g: bench.poses(g, nodes) for g in ("calibration", "test")}
    cmds = {}
    for g, p in poses.items():
        stages = {k: v for k, v in stage_commands(bench, cal, p).items() if k != "uncalibrated"}
        cmds[g] = with_control(stages)  # "OLS again", scored last
    layers, _ = score(bench, poses, cmds)  # every stage from the same clock
    params = {
        m: {"bias_parameter": e.bias_parameter, "scale_parameter": e.scale_parameter}
        for m, (e, _) in cal.estimates.items()
    }
    return {"seed": int(seed), "layers": layers, "estimators": params}


def _spread(values: np.ndarray) -> dict[str, float]:
    p05, med, p95 = np.percentile(values, [5.0, 50.0, 95.0])
    return {"median": float(med), "p05": float(p05), "p95": float(p95)}


def aggregate(results: list[dict[str, Any]], labels: list[str]) -> dict[str, Any]:
    """Per group and estimator: (estimator - OLS) spread and the fraction of wins."""
    out: dict[str, Any] = {"n": len(results), "groups": {}}
    for g in GROUPS:
        block: dict[str, Any] = {}
        for stage in ["coarse", "ols", *labels]:
            vals = {q: np.array([r["layers"][g][stage][q] for r in results]) for q in QUANTITIES}
            entry: dict[str, Any] = {q: _spread(v) for q, v in vals.items()}
            if stage not in ("coarse", "ols"):
                ols = {q: np.array([r["layers"][g]["ols"][q] for r in results]) for q in QUANTITIES}
                for q in QUANTITIES:
                    entry[f"minus_ols_{q}"] = _spread(vals[q] - ols[q])
                entry["better_fraction"] = float(np.mean(vals["pos_mean_mm"] < ols["pos_mean_mm"]))
                entry["better_fraction_max"] = float(
                    np.mean(vals["pos_max_mm"] < ols["pos_max_mm"])
                )
            block[stage] = entry
        out["groups"][g] = block
    return out


class _Bar:
    """map_draws' progress as a bar on stderr."""

    def __init__(self, name: str, total: int, quiet: bool) -> None:
        self.bar = ProgressBar(name, total, quiet)

    def counter(self, label: str, done: int, total: int, every: int = 1) -> None:
        self.bar.update(done, 0, label)


def run_draws(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t0 = time.perf_counter()
    n = scenario.get("draws.n", int)
    entries = scenario.get("draws.estimators", list, ["ols", "liu", "liu_cv"])
    labels = [estimator_label(e) for e in entries]
    if "ols" not in labels:
        raise ValueError("the draw study compares with OLS: put 'ols' in draws.estimators")
    nodes = scenario.get("scoring.nodes_per_side", int, scenario.get("fine.nodes_per_side", int))
    seed0 = scenario.get("seed", int)
    args = [(str(scenario.path), seed0 + i, entries, nodes) for i in range(n)]
    engine = os.environ.get(ENV_ENGINE) or scenario.get("draws.engine", str, "ray")
    progress.step(f"{n} truth draws (seeds {seed0}..{seed0 + n - 1}) on the {engine} engine")
    bar = _Bar(scenario.name, n, getattr(progress, "quiet", False))
    with engine_env(engine):
        results = map_draws(draw_task, args, bar, "truth draws")
    agg = aggregate(results, [lab for lab in labels if lab != "ols"])
    matches = [paper_match(r["layers"]) for r in results]
    regime = {
        "position_factor": POSITION_FACTOR,
        "both_rows_within_fraction": float(np.mean([m["position_reproduced"] for m in matches])),
        **{
            f"{row}_within_fraction": float(
                np.mean([m["rows"][row]["position_within"] for m in matches])
            )
            for row in ("coarse", "ols")
        },
    }
    test = agg["groups"]["test"]
    control = [
        abs(r["layers"]["test"][CONTROL]["pos_mean_mm"] - r["layers"]["test"]["ols"]["pos_mean_mm"])
        * 1e3
        for r in results
    ]
    per_label = {}
    for lab in ("liu", "liu_paper_deg", "liu_cv"):
        e = test.get(lab, {})
        per_label[f"{lab}_better_fraction"] = e.get("better_fraction")
        per_label[f"{lab}_minus_ols_test_pos_mean_mm"] = e.get("minus_ols_pos_mean_mm")
        per_label[f"{lab}_minus_ols_test_pos_max_mm"] = e.get("minus_ols_pos_max_mm")
    summary: dict[str, Any] = {
        "scenario": scenario.name,
        "study": "liu_vs_ols_draws",
        "truth_random": scenario.section("truth").get("random"),
        "truth_effects": [e.get("kind") for e in scenario.get("truth.effects", list, [])],
        "engine": engine,
        "draws": {
            "n": n,
            "seeds": [seed0, seed0 + n - 1],
            # liu: the Liu-type estimator with the HKB k; liu_paper_deg: the paper's
            **per_label,
            "groups": agg["groups"],
        },
        "scoring": {
            "clock": "same",
            # the largest |OLS again - OLS| of any draw, test layer mean, um
            "order_control_um": float(max(control)) if control else None,
        },
        # how often a draw of the truth reproduces the paper's coarse and OLS rows
        "paper_regime": regime,
        "per_draw": results,
        "paper": PAPER,
    }
    from scenarios.studies.liu_vs_ols.draws_figures import draws_figure

    summary["figures"] = draws_figure(out_dir, results, [lab for lab in labels if lab != "ols"])
    for name, file in summary["figures"].items():  # the distribution, beside the report
        recorder.log_figure(name, out_dir / file, "estimator minus OLS over the draws")
    summary["runtime_s"] = time.perf_counter() - t0
    recorder.log_report(scenario.study, summary)
    return summary
