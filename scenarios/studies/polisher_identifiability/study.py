"""Identifiability of the hybrid polisher's source errors under the first paper's plan (4.1).

Builds the identification Jacobian H two ways (the twin's implicit-function form and the
paper's screw-theory model), checks both against finite differences of the full nonlinear
forward kinematics, and reconstructs a column-full-rank H by spectral decomposition, by the
paper's Steps 1-3 (H_xi kept first) and by deterministic pivoted QR.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.analysis import (
    PolisherScrewModel,
    analyse,
    correlation_reconstruction,
    spectral_reconstruction,
)
from calib.fit import CalibrationModel
from scenarios.config import Scenario
from scenarios.machine_setup import load_nominal
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from twin.kinematics import forward
from twin.workspace import commands_for_poses, layer_poses

# The paper's Table 2: irreducible parameters per limb (54 in all).
PAPER_TABLE2 = {"limb1": 8, "limb2": 10, "limb3": 10, "limb4 (UP limb + wrist)": 26, "total": 54}
PAPER_SOURCE_ERRORS = 145


# a share this close to one half is one half (round-off of an orthogonal projection: 1e-15)
HALF_TOL = 1e-9


def group_relative_error(a: np.ndarray, b: np.ndarray, is_angle: np.ndarray) -> float:
    """max |a - b| over each unit group (length / angle columns), relative to that group's
    largest entry of ``a``: columns that are zero in theory are compared on the same scale."""
    worst = 0.0
    for mask in (~is_angle, is_angle):
        if np.any(mask):
            ref = np.max(np.abs(a[:, mask]))
            if ref > 0:
                worst = max(worst, float(np.max(np.abs(a[:, mask] - b[:, mask])) / ref))
    return worst


def fd_jacobian(model: CalibrationModel, commands: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """Central finite differences of the full closed-chain solve, (P*T*3, n)."""
    n = model.n_parameters
    cols = []
    for k in range(n):
        dx = np.zeros(n)
        dx[k] = eps
        plus = model.predict(dx, commands).targets.reshape(-1)
        minus = model.predict(-dx, commands).targets.reshape(-1)
        cols.append((plus - minus) / (2 * eps))
    return np.array(cols).T


def plan_comparison(
    scenario: Scenario,
    model: CalibrationModel,
    params,
    kept: list[int],
    progress: Progress,
) -> list[dict[str, Any]]:
    """Translation-only layer plans: what each identifies and how well conditioned the paper
    plan's identifiable set is under it (same columns, so the numbers compare)."""
    out = []
    half = tuple(v * 1e-3 for v in scenario.get("plan.half_width_mm", list))
    zero = np.zeros(len(params))
    for entry in scenario.get("plan_comparison.plans", list, []):
        heights = [h * 1e-3 for h in entry["layer_heights_mm"]]
        nodes = int(entry["nodes_per_side"])
        poses = layer_poses(model.nominal, heights, nodes, half)
        h = model.jacobian(zero, model.predict(zero, commands_for_poses(model.nominal, poses)))
        n_id = spectral_reconstruction(h).rank  # equals the Steps 1-3 count (tested)
        cols = sorted(kept)
        cond = analyse(h[:, cols], [params.names[k] for k in cols])
        # OLS spread for 0.005 mm noise, in mm and deg (Eq. 18 of the first paper):
        # columns per display unit, rows in mm
        per_unit = np.where(params.is_angle[cols], np.radians(1.0), 1e-3)
        h_disp = h[:, cols] * per_unit * 1e3
        spread = 0.005 * float(np.sqrt(np.trace(np.linalg.inv(h_disp.T @ h_disp))))
        out.append(
            {
                "layer_heights_mm": entry["layer_heights_mm"],
                "nodes_per_side": nodes,
                "n_poses": len(poses),
                "n_identifiable": n_id,
                "condition_number_of_paper_set": cond.condition_number
                if cond.n_identifiable == len(kept)
                else None,
                "ols_overall_std_for_0.005mm_noise": spread,
            }
        )
        progress.note(
            f"plan {entry['layer_heights_mm']} x {nodes}^2: {n_id} identifiable, "
            f"cond {out[-1]['condition_number_of_paper_set']}"
        )
    return out


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t0 = time.perf_counter()
    nominal, params = load_nominal(scenario)
    model = CalibrationModel(nominal, params)
    heights = [h * 1e-3 for h in scenario.get("plan.layer_heights_mm", list)]
    nodes = scenario.get("plan.nodes_per_side", int)
    half = tuple(v * 1e-3 for v in scenario.get("plan.half_width_mm", list))
    poses = layer_poses(nominal, heights, nodes, half)
    progress.step(f"plan: {len(heights)} layers x {nodes} x {nodes} nodes = {len(poses)} poses")
    commands = commands_for_poses(nominal, poses)
    x0 = np.zeros(len(params))
    pred = model.predict(x0, commands)
    progress.step("identification Jacobian: implicit function over the closed chain")
    h_twin = model.jacobian(x0, pred)
    progress.step("identification Jacobian: screw-theory model (Eqs. 1-9, Appendix A)")
    screw = PolisherScrewModel(nominal.copy(), params)
    h_screw = np.vstack([screw.target_matrix(q) for q in pred.qpos])
    screw_err = group_relative_error(h_twin, h_screw, params.is_angle)

    n_fd = scenario.get("checks.fd_poses", int, 3)
    progress.step(f"finite differences of the full forward kinematics at {n_fd} poses")
    fd_idx = np.linspace(0, len(poses) - 1, n_fd).astype(int)
    h_fd = fd_jacobian(model, commands[fd_idx])
    rows = np.concatenate([np.arange(k * 9, k * 9 + 9) for k in fd_idx])
    fd_err = group_relative_error(h_fd, h_twin[rows], params.is_angle)

    progress.step("identifiability: spectral, Steps 1-3, pivoted QR")
    xi = np.array([n.endswith(".encoder") for n in params.names])
    spectral = spectral_reconstruction(h_twin)
    kept = correlation_reconstruction(h_twin, params.names, xi)
    kept_names = [params.names[k] for k in sorted(kept)]
    qr_report = analyse(h_twin, params.names)
    steps_report = analyse(h_twin[:, sorted(kept)], [params.names[k] for k in sorted(kept)])
    per_limb = {f"limb{i}": sum(n.startswith(f"limb{i}.") for n in kept_names) for i in (1, 2, 3)}
    per_limb["limb4 (UP limb + wrist)"] = sum(n.startswith("limb4.") for n in kept_names)
    strip = [n.split(".", 1)[1] for n in kept_names if n.startswith("limb2.")]
    strip3 = [n.split(".", 1)[1] for n in kept_names if n.startswith("limb3.")]
    plans = plan_comparison(scenario, model, params, kept, progress)
    recorder.log_mechanism(nominal)
    for i, q in enumerate(pred.qpos):
        recorder.log_pose("node", i, nominal, q)
    recorder.log_text("identifiable", "\n".join(f"* {n}" for n in kept_names), "identifiable set")

    from scenarios.studies.polisher_identifiability.figures import null_space_png, spectrum_png
    from scenarios.studies.polisher_identifiability.null_space import null_space
    from scenarios.studies.polisher_identifiability.report import groups_markdown

    _, rank_fig = spectrum_png(
        out_dir / "singular_values.png",
        h_twin,
        f"polisher, {len(poses)} poses:\ncolumn-scaled H of the {len(params)} source errors",
    )
    seen = null_space(h_twin, list(params.names))
    null_space_png(out_dir / "null_space.png", seen, list(params.names))
    # a member of a pair whose difference alone is unseen has a share of exactly one half; its
    # round-off (1e-16) must not decide "mostly", or the count follows the BLAS threads
    in_null = [params.names[i] for i in np.flatnonzero(seen.share > 0.5 + HALF_TOL)]
    null_summary = seen.summary(list(params.names))
    # the report's figures, static: the singular values on their log axis, where the rank is
    recorder.log_figure("singular_values", out_dir / "singular_values.png", "singular values of H")
    recorder.log_figure("null_space", out_dir / "null_space.png", "what the plan cannot see")
    recorder.log_text("combinations", groups_markdown(null_summary), "read only as combinations")
    # a wrist angle or node outside the plan raises before this point (WorkspaceError)
    summary = {
        "scenario": scenario.name,
        "model": nominal.name,
        "n_source_errors": len(params),
        "paper_source_errors": PAPER_SOURCE_ERRORS,
        "n_poses": len(poses),
        "n_equations": int(h_twin.shape[0]),
        "n_identifiable": len(kept),
        "rank_spectral": spectral.rank,
        "rank_pivoted_qr": qr_report.rank,
        "identifiable": kept_names,
        "identifiable_pivoted_qr": list(qr_report.identifiable),
        "identifiable_per_limb": per_limb,
        "limbs_2_and_3_alike": strip == strip3,
        "paper_table2_per_limb": PAPER_TABLE2,
        "condition_number": steps_report.condition_number,
        "condition_number_pivoted_qr": qr_report.condition_number,
        "smallest_singular_values": spectral.eigenvalues[-5:] ** 0.5,
        "no_effect": [n for n, why in qr_report.unidentifiable.items() if "no effect" in why],
        "jacobian_fd_max_rel_err": fd_err,
        "screw_vs_twin_max_rel_err": screw_err,
        "home_check_residual_m": forward(nominal, commands[0]).residual,
        "plans": plans,
        "figures": {"singular_values": "singular_values.png", "null_space": "null_space.png"},
        "rank_of_figure": rank_fig,
        "mostly_in_null_space": in_null,
        "null_space": null_summary,
        "runtime_s": time.perf_counter() - t0,
    }
    recorder.log_report(scenario.study, summary)
    return summary
