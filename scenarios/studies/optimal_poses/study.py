"""Measurement design on the hexapod: the second paper's optimal poses against random ones.

1. Candidates: the 64 extremes of its Table 3 workspace. None of them is reachable within the
   195..265 mm stroke, so each is pulled back along the segment from the workspace centre to
   the farthest reachable pose (twin.workspace.boundary_poses).
2. The paper's algorithm (its Fig. 9): greedy one-by-one addition of the pose that most
   improves the condition number (its Eq. 7), from 30 random sets of 9, until the index stops
   improving; and ours: a DETMAX exchange maximising D-optimality over the boundary poses plus
   random reachable poses, at the same count.
3. With the Table 2 truth and the paper's pose noise, each set is identified by LM over many
   noise draws: the largest parameter error and the verification error on the 216-pose grid
   after compensation (first order: the identified model's residual pose error twist at each
   verification pose, B (truth - estimate)), averaged over the draws. The draws run as sweep
   tasks (scenarios.sweep.draws), one per pose set, since each draw starts from the previous
   draw's estimate: in this process, or on Ray inside a sweep or with RAY_ADDRESS set.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.analysis import exchange, observability, paper_selection, stopping_count
from calib.exceptions import CalibError
from calib.fit import CalibrationModel, Observations, identify
from scenarios.config import Scenario
from scenarios.figures import index_vs_count_png
from scenarios.machine_setup import load_machine
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.studies.optimal_poses.report import index_figure_title
from scenarios.sweep.draws import map_draws
from twin.formats import load_parameter_set
from twin.kinematics import forward_batch, tool_twist_jacobian_batch
from twin.mechanism import Mechanism
from twin.tracker import PoseNoise
from twin.workspace import boundary_poses, grid_poses, random_poses

N_DRAWN_STARTS = 5  # the index figure draws the best start and the first few of the others

PAPER_TABLE4 = {
    "before": {"pos_peak_mm": 0.1496, "ori_peak_deg": 0.0247},
    "random_256": {"pos_peak_mm": 0.0280, "ori_peak_deg": 0.0069},
    "optimal_29": {"pos_peak_mm": 0.0212, "ori_peak_deg": 0.0047},
    "n_optimal": 29,
}


def _blocks(model: CalibrationModel, commands: np.ndarray) -> list[np.ndarray]:
    zero = np.zeros(model.n_parameters)
    jac = model.jacobian(zero, model.predict(zero, commands))
    rows = 3 * model.nominal.n_targets
    return [jac[k * rows : (k + 1) * rows] for k in range(len(commands))]


def identify_noise_draws(
    model_path: str,
    error_model_path: str,
    commands: np.ndarray,
    measured: np.ndarray,
    truth_values: np.ndarray,
    b_ver: np.ndarray,
) -> dict[str, Any]:
    """One pose set identified by LM over its noise draws (``measured``: (D, N, T, 3)), each
    draw starting from the previous draw's estimate (one calibration model for all, so the
    closure solves start from the previous draw's configurations); a sweep task (plain data
    in and out).

    Returns the largest parameter error (mm, deg) and the verification peaks (mm, deg) of each
    draw that converged, and how many did not."""
    nominal = Mechanism.from_xml(model_path)
    params = load_parameter_set(error_model_path, nominal.model)
    out: dict[str, Any] = {"param": [], "pos": [], "ori": [], "failed": 0}
    start = np.zeros(len(params))
    model = CalibrationModel(nominal, params)  # a draw's closure solves start from the last
    for readings in measured:
        try:
            res = identify(model, Observations(commands, readings), x0=start)
        except CalibError:
            out["failed"] += 1
            continue
        start = res.values  # the next draw starts from this estimate
        err = truth_values - res.values
        twist = b_ver @ err  # (V, 6)
        out["param"].append(float(np.max(np.abs(params.to_display(err)))))
        out["pos"].append(float(np.max(np.linalg.norm(twist[:, :3], axis=1))) * 1e3)
        out["ori"].append(float(np.degrees(np.max(np.linalg.norm(twist[:, 3:], axis=1)))))
    return out


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t_start = time.perf_counter()
    rng = np.random.default_rng(scenario.get("seed", int))
    machine = load_machine(scenario, rng)
    nominal, params, truth = machine.nominal, machine.params, machine.truth
    truth_values = machine.truth_values
    model = machine.calibration_model()
    noise = PoseNoise(
        kind=scenario.get("pose_noise.kind", str),
        position_m=scenario.get("pose_noise.position_mm", float) * 1e-3,
        rotation_rad=np.radians(scenario.get("pose_noise.rotation_deg", float)),
    )

    progress.step("candidates: the 64 workspace extremes, pulled back into the strokes")
    b_poses, b_cmds = boundary_poses(nominal)
    b_blocks = _blocks(model, b_cmds)
    index = scenario.get("design.index", str, "condition")
    n_starts = scenario.get("design.random_starts", int)
    n_initial = scenario.get("design.initial_poses", int)
    until = scenario.get("design.max_poses", int)
    progress.step(f"the paper's greedy selection: {n_starts} starts of {n_initial} poses")
    best, runs = paper_selection(b_blocks, rng, n_starts, n_initial, until, index)
    n_opt = stopping_count(best)
    optimal = best.indices[:n_opt]
    progress.note(f"index stops improving at {n_opt} poses")

    recorder.log_mechanism(nominal)
    for i, q in enumerate(forward_batch(nominal, b_cmds[optimal]).qpos):
        recorder.log_pose("optimal_pose", i, nominal, q)
    progress.step("our design: D-optimal exchange over boundary + random reachable poses")
    n_extra = scenario.get("design.extra_random_candidates", int)
    _, r_cmds = random_poses(nominal, n_extra, rng)
    all_cmds = np.vstack([b_cmds, r_cmds])
    all_blocks = b_blocks + _blocks(model, r_cmds)
    ex_idx, _ = exchange(all_blocks, list(optimal), "d_optimality")

    n_random_many = scenario.get("evaluation.random_many", int)
    _, rand_same_cmds = random_poses(nominal, n_opt, rng)
    _, rand_many_cmds = random_poses(nominal, n_random_many, rng)
    sets = {
        "optimal": b_cmds[optimal],
        "exchange": all_cmds[ex_idx],
        "random_same_count": rand_same_cmds,
        "random_256": rand_many_cmds,
    }
    set_jacobians = {  # the candidates' blocks computed once, the random sets' once each
        "optimal": np.vstack([all_blocks[k] for k in optimal]),
        "exchange": np.vstack([all_blocks[k] for k in ex_idx]),
        "random_same_count": np.vstack(_blocks(model, rand_same_cmds)),
        "random_256": np.vstack(_blocks(model, rand_many_cmds)),
    }
    indices = {
        name: {k: observability(jac, k) for k in ("condition", "d_optimality")}
        for name, jac in set_jacobians.items()
    }

    progress.step("verification grid and its pose-error Jacobians")
    _, v_cmds = grid_poses(nominal, 3, 8, rng, margin=0.25, stroke_margin=2e-3)
    v_qpos = forward_batch(truth, v_cmds).qpos
    # (V, 6, n): truth side of the scoring only
    b_ver = tool_twist_jacobian_batch(truth, params, truth_values, v_qpos)

    draws = scenario.get("evaluation.noise_draws", int)
    local = nominal.target_local()
    clean = {name: forward_batch(truth, c) for name, c in sets.items()}
    measured: dict[str, list[np.ndarray]] = {n: [] for n in sets}
    for _ in range(draws):  # the noise of every draw, drawn in the order the loop drew it
        for name in sets:
            sol = clean[name]
            r_n, p_n = noise.perturb(sol.tool_rotation, sol.tool_position, rng)
            measured[name].append(np.einsum("nij,tj->nti", r_n, local) + p_n[:, None, :])
    progress.step(f"identification over {draws} noise draws, one task per pose set")
    files = (
        str(scenario.resolve(scenario.get("model", str), "model")),
        str(scenario.resolve(scenario.get("error_model", str), "error_model")),
    )
    chains = map_draws(
        identify_noise_draws,
        [(*files, sets[n], np.stack(measured[n]), truth_values, b_ver) for n in sets],
        progress,
        "pose sets identified over the noise draws",
    )
    results = dict(zip(sets, chains, strict=True))
    failures = {n: r["failed"] for n, r in results.items()}

    def mean(v: list[float]) -> float | None:
        return float(np.mean(v)) if v else None

    summary_sets = {
        name: {
            "n_poses": len(sets[name]),
            "param_max_abs_mm": mean(r["param"]),
            "verify_pos_peak_mm": mean(r["pos"]),
            "verify_ori_peak_deg": mean(r["ori"]),
            "param_max_abs_mm_std": float(np.std(r["param"])) if r["param"] else None,
            "failed_draws": failures[name],
            **{f"index_{k}": v for k, v in indices[name].items()},
        }
        for name, r in results.items()
    }
    counts = list(range(best.start_count, best.start_count + len(best.index_by_count)))
    index_vs_count_png(
        out_dir / "index_vs_count.png",
        index_figure_title(index, len(runs), len(runs[:N_DRAWN_STARTS])),
        counts,
        {
            "best start": best.index_by_count,
            **{f"start {k}": r.index_by_count for k, r in enumerate(runs[:N_DRAWN_STARTS])},
        },
        f"{index} (column-scaled, log)",
        stop=n_opt,
    )
    recorder.log_figure(
        "index_vs_count", out_dir / "index_vs_count.png", f"{index} index by pose count"
    )
    summary = {
        "scenario": scenario.name,
        "model": nominal.name,
        "figures": {"index_vs_count": "index_vs_count.png"},
        "index": index,
        "index_by_count": best.index_by_count,
        "index_counts": list(range(best.start_count, best.start_count + len(best.index_by_count))),
        "random_start_finals": [r.final for r in runs],
        "n_optimal": n_opt,
        "n_noise_draws": draws,
        "n_candidates_boundary": len(b_poses),
        "n_candidates_exchange": len(all_blocks),
        "optimal": summary_sets["optimal"],
        "exchange": summary_sets["exchange"],
        "random_same_count": summary_sets["random_same_count"],
        "random_256": summary_sets["random_256"],
        "paper_table4": PAPER_TABLE4,
        "runtime_s": time.perf_counter() - t_start,
    }
    recorder.log_report(scenario.study, summary)
    return summary
