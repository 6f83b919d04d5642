"""The liu_vs_ols pipeline in steps, shared by the single scenario, the draw study and the
regime map.

The machine (truth twin with its effects, the tracker, the measurement sequence) is a
:class:`Bench`; the calibration side sees only ``bench.measure`` (commands in, readings out)
and the nominal model. Scoring uses ``bench.true_targets`` (where the targets really are).

Fair scoring. The twin's time-dependent effects (thermal growth: a temperature that rises
with every pose measured) would make a stage re-measured later meet a warmer machine, and
the order of the stages would decide which estimator wins. :func:`score` therefore measures
every stage of every group from the same clock: the machine as it stands when scoring
begins, each stage's k-th pose at the same pose of the sequence (a careful experimenter
lets the machine return to the same state, or interleaves the stages). An "OLS again"
control (:data:`CONTROL`), OLS's commands scored once more after every other stage, shows
that the order no longer matters: its error equals OLS's to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from calib.analysis import PoseErrors, max_mean_stats, pose_errors
from calib.compensate import TwistCompensation
from calib.estimators import LinearEstimate
from calib.fit import CalibrationModel
from calib.two_step import CoarseResult, FineProblem, coarse_calibration, estimate, fine_problem
from scenarios.config import Scenario
from scenarios.machine_setup import ScenarioMachine, build_effects, load_machine
from twin.kinematics import commands_near, forward_batch, one_blas_thread
from twin.measurement import measure as twin_measure
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import checked_commands, layer_poses

# First paper, Table 5 (experiment, "pose errors after calibration in three measurement
# layers") and section 5 (simulation).
PAPER: dict[str, Any] = {
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
# Our stage beside each row of the paper's Table 5: its Liu row is the paper's estimator
# (Eq. 11 with k = 1 on H in mm and deg), not the Liu-type estimator with the HKB k.
PAPER_ROW_OF = {"coarse": "coarse", "ols": "ols", "liu": "liu_paper_deg"}
POSITION_FACTOR = 1.5
MATCHED_ROWS = ("coarse", "ols")


@dataclass
class Bench:
    """The truth twin as the calibration meets it: commands in, tracker readings out."""

    scenario: Scenario
    rng: np.random.Generator
    machine: ScenarioMachine
    model: CalibrationModel
    encoder: np.ndarray
    sigma_m: float
    tracker: Tracker
    effects: list
    half: tuple[float, float]
    z_layers: dict[str, float]
    clock: list[int] = field(default_factory=lambda: [0])  # poses measured so far

    def _order(self, n: int, order: np.ndarray | None) -> np.ndarray:
        """The poses' places in the measurement sequence: the next ``n`` poses, or ``order``
        as given (scoring from a fixed clock); the clock then stands after the latest."""
        if order is None:
            order = self.clock[0] + np.arange(n)
        order = np.asarray(order, dtype=int)
        if order.shape != (n,):
            raise ValueError(f"{n} commands but an order of shape {order.shape}")
        self.clock[0] = max(self.clock[0], int(order.max(initial=-1)) + 1)
        return order

    def run_machine(self, commands: np.ndarray, order: np.ndarray | None = None):
        """The truth twin with its effects, at the next poses of the measurement sequence
        (or at the places ``order`` gives)."""
        order = self._order(len(commands), order)
        return twin_measure(
            self.machine.truth, commands, self.tracker, self.rng, effects=self.effects, order=order
        )

    def measure(self, commands: np.ndarray) -> np.ndarray:
        """Tracker readings (N, T, 3) of the targets, averaged over the repeats."""
        if not self.effects:  # geometry only: the twin's direct path
            self.clock[0] += len(commands)
            return self.tracker.measure_averaged(
                forward_batch(self.machine.truth, commands).targets, self.rng
            )
        return self.run_machine(commands).readings.mean(axis=2)

    def true_targets(self, commands: np.ndarray, order: np.ndarray | None = None) -> np.ndarray:
        """Where the targets really are (no tracker noise), for scoring; ``order``: the
        poses' places in the measurement sequence (default: the next ones)."""
        if not self.effects:
            self._order(len(commands), order)
            return forward_batch(self.machine.truth, commands).targets
        return self.run_machine(commands, order).true_targets

    def poses(self, group: str, nodes: int) -> np.ndarray:
        heights = {
            "calibration": [self.z_layers["upper"], self.z_layers["lower"]],
            "test": [self.z_layers["middle"]],
            "fine": [self.z_layers["upper"], self.z_layers["lower"]],
            "coarse": [self.z_layers["middle"]],
        }[group]
        return layer_poses(self.machine.nominal, heights, nodes, self.half)


def make_bench(scenario: Scenario, rng: np.random.Generator | None = None) -> Bench:
    rng = np.random.default_rng(scenario.get("seed", int)) if rng is None else rng
    machine = load_machine(scenario, rng)
    params = machine.params
    sigma = scenario.get("tracker.sigma_mm", float) * 1e-3
    tracker = Tracker(
        position_m=tuple(v * 1e-3 for v in scenario.get("tracker.position_mm", list)),
        noise=TrackerNoise("gaussian", sigma, 0.0),
        repeats=scenario.get("tracker.repeats", int, 1),
    )
    return Bench(
        scenario=scenario,
        rng=rng,
        machine=machine,
        model=machine.calibration_model(),
        encoder=np.array([n.endswith(".encoder") for n in params.names]),
        sigma_m=sigma,
        tracker=tracker,
        effects=build_effects(scenario),
        half=tuple(v * 1e-3 for v in scenario.get("workspace.half_width_mm", list)),
        z_layers={k: v * 1e-3 for k, v in scenario.section("layers").items()},
    )


@dataclass(frozen=True)
class Calibration:
    coarse: CoarseResult
    fine_poses: np.ndarray
    fine_order: np.ndarray  # measurement order of the fine plan's poses
    fine_commands: np.ndarray  # (N, A) at the coarse settings
    fine_measured: np.ndarray  # (N, T, 3) readings
    problem: FineProblem
    estimates: dict[str, tuple[LinearEstimate, np.ndarray]]


def estimator_label(entry: str | dict[str, Any]) -> str:
    return entry if isinstance(entry, str) else entry["label"]


def run_estimators(problem: FineProblem, entries: list) -> dict[str, tuple[LinearEstimate, Any]]:
    """Each entry: "ols", or a table {label = "liu_k1", method = "liu", k = 1.0}.

    Each runs on one BLAS thread (small matrices; the same numbers whatever the caller's
    BLAS setting)."""
    out = {}
    for entry in entries:
        if isinstance(entry, str):
            method, opts = entry, {}
        else:
            method = entry["method"]
            opts = {k: v for k, v in entry.items() if k not in ("label", "method")}
        with one_blas_thread():
            out[estimator_label(entry)] = estimate(problem, method, **opts)
    return out


def calibrate(bench: Bench, entries: list, progress=None) -> Calibration:
    """Coarse (middle layer, Eq. 15) then fine (upper and lower layers, every estimator)."""
    sc = bench.scenario
    coarse_nodes = sc.get("coarse.nodes_per_side", int)
    fine_nodes = sc.get("fine.nodes_per_side", int)
    if progress is not None:
        progress.step(f"coarse calibration: middle layer, {coarse_nodes} x {coarse_nodes} nodes")
    # the coarse and fine problems and the estimators on one BLAS thread (small matrices)
    with one_blas_thread():
        coarse = coarse_calibration(
            bench.model,
            bench.encoder,
            bench.poses("coarse", coarse_nodes),
            bench.measure,
            rel_tol=sc.get("coarse.rel_tol", float, 0.05),
        )
    if progress is not None:
        progress.note(
            f"{coarse.iterations} rounds, relative changes "
            + ", ".join(f"{c:.3g}" for c in coarse.relative_changes)
        )
        progress.step(
            f"fine calibration: upper and lower layers, {fine_nodes} x {fine_nodes} nodes"
        )
    fine_poses = bench.poses("fine", fine_nodes)
    order = bench.clock[0] + np.arange(len(fine_poses))
    seen: list[tuple[np.ndarray, np.ndarray]] = []

    def measure(commands: np.ndarray) -> np.ndarray:
        readings = bench.measure(commands)
        seen.append((np.array(commands), readings))
        return readings

    with one_blas_thread():
        problem = fine_problem(bench.model, coarse.values, bench.encoder, fine_poses, measure)
    ((cmds, readings),) = seen
    estimates = run_estimators(problem, entries)
    return Calibration(coarse, fine_poses, order, cmds, readings, problem, estimates)


def stage_commands(
    bench: Bench,
    cal: Calibration,
    poses: np.ndarray,
    stages: list[str] | None = None,
    comp: TwistCompensation | None = None,
) -> dict[str, np.ndarray]:
    """Commands of every stage for ``poses``: uncalibrated, coarse, each estimator (Eq. 16).

    ``comp``: Eq. 16's preparation of ``poses`` on the coarse model, when the caller has it.
    The coarse commands are its first inverse kinematics (the same solves, pose after pose
    from the home configuration, on the same model), checked against the workspace and the
    strokes as :func:`twin.workspace.commands_for_poses` does."""
    nominal = bench.machine.nominal
    if comp is None:
        comp = TwistCompensation.prepare(bench.model, cal.coarse.values, poses)
    coarse_mech = bench.model.mechanism(cal.coarse.values)
    out = {
        # before any calibration: commands_for_poses's, solved from the coarse model's
        "uncalibrated": commands_near(nominal, poses, comp.qpos, comp.actuator_jacobians),
        "coarse": checked_commands(coarse_mech, poses, comp.qpos[:, coarse_mech.actuator_qpos]),
    }
    deltas = {m: est.x for m, (est, _) in cal.estimates.items() if stages is None or m in stages}
    out.update({m: comp.commands(delta, cal.problem.columns) for m, delta in deltas.items()})
    return out


CONTROL = "ols_again"  # OLS's commands scored once more, after every other stage
Clock = Literal["same", "sequential"]


def with_control(stage_cmds: dict[str, Any], reference: str = "ols") -> dict[str, Any]:
    """The stages with the "OLS again" control appended last (the reference's commands)."""
    if reference not in stage_cmds:
        return dict(stage_cmds)
    return {**stage_cmds, CONTROL: stage_cmds[reference]}


def order_control_um(layers: dict[str, dict[str, dict[str, float]]], group: str = "test") -> float:
    """Mean position error of the "OLS again" control minus OLS's in ``group``, um: zero
    to round-off when every stage is scored on the same machine state."""
    g = layers[group]
    return (g[CONTROL]["pos_mean_mm"] - g["ols"]["pos_mean_mm"]) * 1e3


def score(
    bench: Bench,
    poses: dict[str, np.ndarray],
    cmds: dict[str, dict[str, np.ndarray]],
    clock: Clock = "same",
) -> tuple[dict[str, dict[str, dict[str, float]]], dict[str, dict[str, Any]]]:
    """Re-measure every stage's commands on the truth: stats per group, and the error maps.

    ``poses[group]`` and ``cmds[group][stage]`` for any groups (the liu_vs_ols study's are
    "calibration" and "test"; the group "all" is then the union of both, the paper's three
    layers, not measured again). ``clock="same"`` (fair scoring) measures every stage of
    every group from the clock at which scoring begins, so a time-dependent effect is the
    same for each; ``"sequential"`` measures one stage after the other as the sequence runs
    on (the machine warmer for each later stage: only to show what that does)."""
    if clock not in ("same", "sequential"):
        raise ValueError(f"clock must be 'same' or 'sequential', got {clock!r}")
    layers: dict[str, dict[str, dict[str, float]]] = {}
    maps: dict[str, dict[str, tuple[np.ndarray, PoseErrors]]] = {}
    local = bench.machine.nominal.target_local()
    start = bench.clock[0]
    for group, stage_cmds in cmds.items():
        layers[group], maps[group] = {}, {}
        for stage, c in stage_cmds.items():
            first = start if clock == "same" else bench.clock[0]
            order = first + np.arange(len(poses[group]))
            if callable(c):  # commands that depend on when they are run: c(order)
                c = c(order)
            errs = pose_errors(poses[group], bench.true_targets(c, order), local)
            layers[group][stage] = max_mean_stats(errs)
            maps[group][stage] = (poses[group], errs)
    if "calibration" in maps and "test" in maps:
        layers["all"] = {}
        for stage in maps["test"]:
            if stage not in maps["calibration"]:
                continue
            a, b = maps["calibration"][stage][1], maps["test"][stage][1]
            both = PoseErrors(
                np.concatenate([a.position, b.position]),
                np.concatenate([a.orientation, b.orientation]),
                np.vstack([a.position_vectors, b.position_vectors]),
            )
            layers["all"][stage] = max_mean_stats(both)
    return layers, maps


def paper_match(layers: dict[str, dict[str, dict[str, float]]]) -> dict[str, Any]:
    """Ours / paper for every number of the coarse, OLS and Liu rows (all three layers; the
    paper's Liu row against its own estimator, ``liu_paper_deg``)."""
    out: dict[str, Any] = {"position_factor": POSITION_FACTOR, "rows": {}}
    for stage, paper in PAPER["table5"].items():
        ours = layers["all"].get(PAPER_ROW_OF[stage])
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
