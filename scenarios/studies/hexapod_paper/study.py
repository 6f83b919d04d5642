"""The second paper's simulation study on the 6-RRRPRR hexapod (Han et al. 2019).

(a) 9 random poses, no noise: recover the 54 errors of its Table 2;
(b) pose noise uniform +-0.02 mm / +-0.004 deg: 29 random poses against 256 random poses;
(c) verification on 216 poses (3 x 3 x 3 nodes, 8 orientations each) before and after
    compensation, as in its Table 6 (the commands by the solve ``pkm-calib compensate`` uses);
(d) the calibrated model exported (what ``pkm-calib export`` writes) and its kinematics checked.
The calibration side sees only the nominal model, the error model and Dataset files.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calib.analysis import error_stats, pose_errors
from calib.compensate import kinematics_difference, reachable_compensated_commands
from calib.exceptions import CalibError
from calib.fit import CalibrationModel, IdentificationResult, bind_dataset, identify
from common.atomic_files import write_text_atomic
from scenarios.config import Scenario
from scenarios.figures import parameter_bars_png
from scenarios.machine_setup import load_machine
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.twin_datasets import measured_dataset, through_file
from twin.formats import mjcf_with_values
from twin.kinematics import forward_batch, pose_to_frame
from twin.mechanism import Mechanism
from twin.tracker import PoseNoise, Tracker, TrackerNoise
from twin.workspace import grid_poses, random_poses

PAPER = {
    "recovery_29_random_max_abs_mm": 1.1,  # section "Structural parameter identification"
    "recovery_256_random_max_abs_mm": 0.015,
    "table6_before": {
        "pos_peak_mm": 0.534,
        "pos_std_mm": 0.076,
        "ori_peak_deg": 0.122,
        "ori_std_deg": 0.054,
    },
    "table6_after": {
        "pos_peak_mm": 0.012,
        "pos_std_mm": 0.0047,
        "ori_peak_deg": 0.0051,
        "ori_std_deg": 0.0015,
    },
    "table4_before": {"pos_peak_mm": 0.1496, "pos_std_mm": 0.0673},
    "table4_after_256_random": {"pos_peak_mm": 0.0280, "pos_std_mm": 0.010},
}


@dataclass(frozen=True)
class Case:
    """One identification: its pose plan, what it recovered, and how long it took."""

    name: str
    n_poses: int
    noise: str
    result: IdentificationResult | None
    error: str
    max_abs_mm: float
    runtime_s: float

    def summary(self, truth_display: np.ndarray, params) -> dict[str, Any]:
        out: dict[str, Any] = {"n_poses": self.n_poses, "noise": self.noise}
        if self.result is None:
            out["error"] = self.error
            return out
        r = self.result
        est = params.to_display(r.values)
        dev = est - truth_display
        worst = int(np.nanargmax(np.abs(np.where(r.estimated, dev, np.nan))))
        std = params.to_display(r.std_errors)
        z = np.abs(dev) / np.where(std > 0, std, np.nan)
        out.update(
            max_abs_mm=self.max_abs_mm,
            worst_parameter=r.names[worst],
            worst_std_error_mm=float(std[worst]),
            max_abs_over_std=float(np.nanmax(z)) if np.any(np.isfinite(z)) else None,
            worst_over_std=float(z[worst]) if np.isfinite(z[worst]) else None,
            n_estimated=int(np.sum(r.estimated)),
            strongest_correlations=strongest_correlations(r, 3),
            rms_abs_mm=float(np.sqrt(np.mean(dev[r.estimated] ** 2))),
            n_identifiable=r.report.n_identifiable,
            condition_number=r.report.condition_number,
            iterations=r.iterations,
            converged=r.converged,
            residual_rms_mm=r.residual_rms * 1e3,
            runtime_s=self.runtime_s,
        )
        return out


def strongest_correlations(r: IdentificationResult, k: int) -> list[dict[str, Any]]:
    """The ``k`` most correlated pairs of estimated parameters (from the covariance)."""
    names = [n for n, e in zip(r.names, r.estimated, strict=True) if e]
    sd = np.sqrt(np.diag(r.covariance))
    if len(names) < 2 or np.any(sd <= 0):
        return []
    corr = r.covariance / np.outer(sd, sd)
    iu = np.triu_indices(len(names), 1)
    order = np.argsort(-np.abs(corr[iu]))[:k]
    return [
        {"a": names[iu[0][i]], "b": names[iu[1][i]], "correlation": float(corr[iu][i])}
        for i in order
    ]


def _identify_case(
    name: str,
    model: CalibrationModel,
    truth: Mechanism,
    poses: np.ndarray,
    commands: np.ndarray,
    tracker: Tracker,
    pose_noise: PoseNoise | None,
    rng: np.random.Generator,
    out_dir: Path,
    truth_values: np.ndarray,
) -> Case:
    t0 = time.perf_counter()
    ds = measured_dataset(truth, commands, poses, name, tracker, rng, pose_noise)
    ds = through_file(ds, out_dir / "datasets" / f"{name}.csv", expected_model=truth.name)
    obs = bind_dataset(model.nominal, ds)
    noise = "none" if pose_noise is None else "pose uniform +-0.02 mm, +-0.004 deg"
    try:
        res = identify(model, obs)
    except CalibError as exc:
        return Case(name, len(poses), noise, None, str(exc), float("nan"), time.perf_counter() - t0)
    dev = model.params.to_display(res.values - truth_values)
    return Case(
        name, len(poses), noise, res, "", float(np.max(np.abs(dev))), time.perf_counter() - t0
    )


def truth_source(scenario: Scenario) -> dict[str, Any]:
    """Where the truth came from: a values file (its path as the scenario names it) or a
    seeded draw from [truth.random] (the seed and the draw's settings)."""
    values_file = scenario.get("truth.values_file", str, None)
    if values_file is not None:
        return {"kind": "values_file", "file": values_file}
    return {
        "kind": "random",
        "seed": scenario.get("seed", int),
        "random": scenario.section("truth").get("random"),
    }


def lm_cost_png(cases: list[Any]) -> bytes:
    """The Levenberg-Marquardt cost of each case against its iterations (log axis)."""
    from scenarios.figures import plt, png_bytes

    fig, ax = plt.subplots(figsize=(7, 4))
    for case in cases:
        if case.result is not None and case.result.history:
            cost = np.asarray(case.result.history, dtype=float)
            ax.semilogy(np.arange(len(cost)), np.maximum(cost, 1e-300), "o-", ms=3, label=case.name)
    ax.set_xlabel("Levenberg-Marquardt iteration")
    ax.set_ylabel("cost: half the sum of squared residuals (m^2, log)")
    ax.set_title("hexapod: identification cost by iteration", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return png_bytes(fig)


def export_check(
    model_path: Path,
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    out: Path,
) -> dict[str, Any]:
    """The nominal MJCF with ``values`` written in (what ``pkm-calib export`` writes), saved to
    ``out``, and its forward kinematics against the identified model's at ``commands``."""
    written = mjcf_with_values(model_path, model.nominal.model, model.params, values)
    exported = Mechanism.from_xml_string(written.text)
    check = kinematics_difference(model.mechanism(values), exported, commands)
    write_text_atomic(out, written.text)
    return {"file": out.name, **check.as_dict()}


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    """Run the study; returns the summary (the runner writes it)."""
    t_start = time.perf_counter()
    rng = np.random.default_rng(scenario.get("seed", int))
    machine = load_machine(scenario, rng)
    nominal, params, truth = machine.nominal, machine.params, machine.truth
    truth_values = machine.truth_values
    truth_display = params.to_display(truth_values)
    model = machine.calibration_model()

    tracker = Tracker(
        position_m=tuple(v * 1e-3 for v in scenario.get("tracker.position_mm", list)),
        noise=TrackerNoise.from_spec(scenario.get("tracker.noise", str)),
        repeats=scenario.get("tracker.repeats", int, 1),
    )
    pose_noise = PoseNoise(
        kind=scenario.get("pose_noise.kind", str),
        position_m=scenario.get("pose_noise.position_mm", float) * 1e-3,
        rotation_rad=np.radians(scenario.get("pose_noise.rotation_deg", float)),
    )
    n_free = scenario.get("plans.noise_free_poses", int)
    n_few = scenario.get("plans.few_poses", int)
    n_many = scenario.get("plans.many_poses", int)

    cases: list[Case] = []
    progress.step("drawing random poses")
    plans = {
        "noise_free": random_poses(nominal, n_free, rng),
        "random_few": random_poses(nominal, n_few, rng),
        "random_many": random_poses(nominal, n_many, rng),
    }
    exact = Tracker(position_m=tracker.position_m, noise=TrackerNoise.none())
    for name, noise in (
        ("noise_free", None),
        ("random_few", pose_noise),
        ("random_many", pose_noise),
    ):
        progress.step(f"identifying from {len(plans[name][0])} poses ({name})")
        case = _identify_case(
            name,
            model,
            truth,
            *plans[name],
            exact if noise is None else tracker,
            noise,
            rng,
            out_dir,
            truth_values,
        )
        cases.append(case)
        progress.note(
            f"{name}: max |error| {case.max_abs_mm:.3g} mm"
            if case.result
            else f"{name}: {case.error.splitlines()[0]}"
        )

    progress.step("verification grid (3 x 3 x 3 nodes x 8 orientations)")
    v_nodes = scenario.get("verification.nodes_per_axis", int)
    v_orient = scenario.get("verification.orientations_per_node", int)
    v_margin = scenario.get("verification.margin", float, 0.0)
    v_stroke = scenario.get("verification.stroke_margin_mm", float, 0.0) * 1e-3
    v_poses, v_cmd_nominal = grid_poses(
        nominal, v_nodes, v_orient, rng, margin=v_margin, stroke_margin=v_stroke
    )
    local = nominal.target_local()

    recorder.log_mechanism(nominal)
    nominal_targets = (
        np.einsum("nij,tj->nti", pose_to_frame(v_poses)[0], local) + v_poses[:, None, :3]
    )

    def verify(commands: np.ndarray, stage: str, ok: np.ndarray | None = None) -> dict:
        ok = np.ones(len(commands), dtype=bool) if ok is None else ok
        sol = forward_batch(truth, commands[ok])  # the true pose, no tracker noise
        errs = pose_errors(v_poses[ok], sol.targets, local)
        recorder.log_error_map(stage, "verification_grid", v_poses[ok, :3], errs.position * 1e3)
        first = np.flatnonzero(ok)[::v_orient]  # one orientation per node
        at = np.searchsorted(np.flatnonzero(ok), first)  # its row in sol
        recorder.log_poses(
            "verification_node",
            range(len(first)),
            truth,
            sol.qpos[at],
            nominal_targets[first],
            sol.targets[at],
            stage,
        )
        stats = error_stats(errs).as_dict()
        stats["n_unreachable_after_compensation"] = int(np.sum(~ok))
        return stats

    summary_verify = {"verify_before": verify(v_cmd_nominal, "before")}
    compensated = {}
    for case in cases[1:]:
        if case.result is None:
            continue
        progress.step(f"compensating and re-measuring ({case.name})")
        cmds, ok = reachable_compensated_commands(model, case.result.values, v_poses)
        key = "verify_after" if case.name == "random_many" else f"verify_after_{case.name}"
        summary_verify[key] = verify(cmds, f"after_{case.name}", ok)
        compensated[case.name] = cmds[ok]

    by_name = {c.name: c for c in cases}
    main = by_name["random_many"].result
    if main is not None:
        progress.step("exporting the calibrated model (random_many), checking its kinematics")
        commands = np.vstack([v_cmd_nominal, compensated["random_many"]])
        summary_verify["export"] = export_check(
            scenario.resolve(scenario.get("model", str), "model"),
            model,
            main.values,
            commands,
            out_dir / "hexapod_calibrated.xml",
        )
        summary_verify["compensation"] = {
            side: {"rms_mm": summary_verify[key]["pos_rms_mm"], "n": summary_verify[key]["n_poses"]}
            for side, key in (("before", "verify_before"), ("after", "verify_after"))
        }
    summary: dict[str, Any] = {
        "scenario": scenario.name,
        "model": nominal.name,
        "truth_source": truth_source(scenario),
        "n_parameters": len(params),
        "n_identifiable": main.report.n_identifiable if main else None,
        "recovery_noise_free_max_abs_mm": by_name["noise_free"].max_abs_mm,
        "recovery_29_random_max_abs_mm": by_name["random_few"].max_abs_mm,
        "recovery_256_random_max_abs_mm": by_name["random_many"].max_abs_mm,
        **summary_verify,
        "n_verification_poses": len(v_poses),
        "cases": {c.name: c.summary(truth_display, params) for c in cases},
        "paper": PAPER,
    }
    if recorder.enabled:
        recorder.log_figure("lm_cost", lm_cost_png(cases), "LM cost by iteration")
    for case in cases:
        if case.result is not None:
            recorder.log_parameters(
                case.name,
                params.names,
                params.to_display(case.result.values),
                params.to_display(case.result.std_errors),
                truth_display,
            )
    if main is not None:
        parameter_bars_png(
            out_dir / "estimates_random_many.png",
            "hexapod: 54 estimates from 256 noisy poses (mm)",
            params.names,
            params.to_display(main.values),
            params.to_display(main.std_errors),
            truth_display,
            "mm",
        )
        summary["figures"] = {"estimates_random_many": "estimates_random_many.png"}
        summary["estimates_random_many"] = {
            n: {"truth_mm": float(t), "estimate_mm": float(e), "std_mm": float(s)}
            for n, t, e, s in zip(
                params.names,
                truth_display,
                params.to_display(main.values),
                params.to_display(main.std_errors),
                strict=True,
            )
        }
    summary["runtime_s"] = time.perf_counter() - t_start
    recorder.log_report(scenario.study, summary)
    return summary
