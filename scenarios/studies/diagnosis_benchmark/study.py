"""A benchmark of the residual diagnosis, not an anecdote: many random truths, one effect each.

A *case* is (machine, twin effect kind or "none", magnitude multiplier, seed). For each case:

1. a random geometric truth (``[truth.random]``, seeded by the case) on the machine, and
   random reachable poses (the workspace box of a parallel machine; joint commands over 80 %
   of each range for a serial arm);
2. ONE twin effect (``scenarios.machine_setup.EFFECTS``, and the encoder's) switched on, its
   magnitude argument (:data:`SCALED`) scaled linearly so that the effect's RMS on the
   readings, per coordinate and noise-free (measured with and without it at a reference
   magnitude), is ``multiplier`` times the tracker noise sigma (per coordinate);
3. calibration, test and audit poses measured in one sequence (calibration, then test, then
   audit: the measurement order continues, so time effects keep growing);
4. geometric identification (``calib.fit.identification.identify``, without outlier rejection: the
   noise is Gaussian, there are no gross outliers to reject, only the effect's own readings)
   on the calibration set, then ``calib.diagnosis.core`` with the test set as the user's
   test set;
5. scoring: the named effect against the truth kind through :data:`ACCEPTED` (twin kind ->
   the diagnosis's candidate names that are a right answer), and the 3D RMS error on the audit
   poses (which neither the fit nor the diagnosis saw) before and after adding the named
   effect; *worse* is after > before * 1.02.

The aggregate is a confusion table (true kind -> named), the rate of right names over cases
with multiplier >= 2 whose effect the geometry did not absorb (:data:`ABSORBED_P`: a rule on
the geometric fit's residual, fixed in advance; the absorbed cases are counted beside the
rate, and the rate with them as misses is reported too), per machine and overall; the
false-alarm rate over "none" cases (anything named but "none") and the count of cases whose
audit error got worse. The cases run through ``scenarios.sweep.draws.map_draws`` (in-process,
or on Ray when asked: ``PKM_ENGINE=ray``), each a plain function of plain arguments.

The twin's effects and the diagnosis's candidates are separate code with separate names: the
diagnosis never imports the twin. Only this benchmark (the truth side) knows both.

The kinds (what is right, how each is sized) are scenarios.studies.diagnosis_benchmark.kinds, the
aggregate scenarios.studies.diagnosis_benchmark.aggregate; both are re-exported here.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.diagnosis import TestSet, diagnose, effect_offsets, effect_target_shifts
from calib.exceptions import CalibError
from calib.fit import CalibrationModel, Observations, identify
from scenarios.config import Scenario
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.studies.diagnosis_benchmark.aggregate import (
    ABSORBED_P,
    STRONG_MULTIPLIER,
    WORSE_FACTOR,
    aggregate,
)
from scenarios.studies.diagnosis_benchmark.figures import write_figures
from scenarios.studies.diagnosis_benchmark.kinds import (
    ACCEPTED,
    EFFECT_TYPES,
    SCALED,
    effect_for,
    is_correct,
    not_applicable,
)
from scenarios.sweep.draws import map_draws
from scenarios.truth_draw import TruthSpec, draw_truth
from twin.formats import load_parameter_set
from twin.kinematics import forward_batch
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses, uniform_commands


def _draw_commands(mech: Mechanism, n: int, fraction: float, rng: np.random.Generator):
    """Commands of random reachable poses: in the workspace box when the model declares one
    (parallel machines), else joint commands uniform over ``fraction`` of each range about
    its middle (a serial arm)."""
    if mech.workspace_min is not None and mech.workspace_max is not None:
        return random_poses(mech, n, rng)[1]
    return uniform_commands(mech, n, fraction, rng)


def _rms_coord(a: np.ndarray, b: np.ndarray) -> float:
    """RMS per coordinate of a - b (3D RMS / sqrt(3))."""
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def _noise_free(truth, commands, head, effects, order):
    tracker = Tracker(position_m=head, noise=TrackerNoise("gaussian", 0.0, 0.0))
    return measure(truth, commands, tracker, np.random.default_rng(0), effects=effects, order=order)


__all__ = [
    "ABSORBED_P",
    "ACCEPTED",
    "EFFECT_TYPES",
    "SCALED",
    "STRONG_MULTIPLIER",
    "WORSE_FACTOR",
    "aggregate",
    "cases",
    "effect_for",
    "is_correct",
    "not_applicable",
    "run",
    "run_case",
]

# What depends only on a case's seed (its truth, its commands, the noise-free readings
# without effect, the rng's state after those draws) and the effect's RMS at its reference
# magnitude are the same for every kind and multiplier of that seed: kept per process, so a
# worker does not redo them; a case's numbers are the same with or without them.
_DRAWS: dict[tuple, tuple] = {}
_REF_RMS: dict[tuple, float] = {}


def _seeded_draw(model_path: str, params_path: str, seed: int, settings: dict[str, Any]):
    """(truth values, commands, noise-free readings, rng after them) of this seed."""
    key = (model_path, params_path, seed, repr(settings))
    if key not in _DRAWS:
        if len(_DRAWS) >= 64:
            _DRAWS.clear()
        rng = np.random.default_rng(seed)
        nominal = Mechanism.from_xml(model_path)
        params = load_parameter_set(params_path, nominal.model)
        values = draw_truth(params, TruthSpec(**settings["truth"]), rng)
        truth = nominal.with_model(params.inject(nominal.model, values))
        n = settings["calibration_poses"] + settings["test_poses"] + settings["audit_poses"]
        commands = _draw_commands(nominal, n, settings.get("joint_fraction", 0.8), rng)
        head = tuple(v * 1e-3 for v in settings["tracker_position_mm"])
        plain = _noise_free(truth, commands, head, [], np.arange(n)).readings[:, :, 0]
        _DRAWS[key] = (values, commands, plain, rng.bit_generator.state)
    values, commands, plain, state = _DRAWS[key]
    rng = np.random.default_rng()
    rng.bit_generator.state = state
    return values, commands, plain, rng


def run_case(
    model_path: str,
    params_path: str,
    machine: str,
    kind: str,
    multiplier: float,
    seed: int,
    settings: dict[str, Any],
) -> dict[str, Any]:
    """One benchmark case, on plain data (a sweep task): the truth, the effect sized to
    ``multiplier`` x the noise, measure, identify, diagnose, score."""
    t0 = time.perf_counter()
    nominal = Mechanism.from_xml(model_path)
    params = load_parameter_set(params_path, nominal.model)
    sigma = settings["sigma_mm"] * 1e-3
    head = tuple(v * 1e-3 for v in settings["tracker_position_mm"])
    n_cal, n_test, n_audit = (
        settings["calibration_poses"],
        settings["test_poses"],
        settings["audit_poses"],
    )
    n = n_cal + n_test + n_audit
    truth_values, commands, plain, rng = _seeded_draw(model_path, params_path, seed, settings)
    truth = nominal.with_model(params.inject(nominal.model, truth_values))
    order = np.arange(n)  # one sequence: calibration, then test, then audit
    out: dict[str, Any] = {
        "machine": machine,
        "kind": kind,
        "multiplier": multiplier,
        "seed": seed,
    }
    exact = plain  # noise-free readings of the truth with its effect
    if kind != "none":
        arg, ref, _, how = SCALED[kind]
        over = settings.get("effect_args", {}).get(kind)
        key = (model_path, params_path, kind, seed, repr(settings))
        if key not in _REF_RMS:
            if len(_REF_RMS) >= 256:
                _REF_RMS.clear()
            at_ref = _noise_free(truth, commands, head, [effect_for(kind, ref, seed, over)], order)
            _REF_RMS[key] = _rms_coord(at_ref.readings[:, :, 0], plain)
        ref_rms = _REF_RMS[key]
        if not ref_rms > 0:
            return {**out, "skipped": f"the effect at {arg} = {ref:g} does not change the readings"}
        ratio = multiplier * sigma / ref_rms
        value = ref * ratio if how == "linear" else ref / ratio
        try:
            effects = [effect_for(kind, value, seed, over)]
        except ValueError as exc:  # e.g. an air temperature no hall has: not a case
            return {**out, "skipped": f"{arg} = {value:.4g} is out of the effect's range: {exc}"}
        exact = _noise_free(truth, commands, head, effects, order).readings[:, :, 0]
        got = _rms_coord(exact, plain)
        out.update(
            scaled_argument=arg,
            argument_value=value,
            effect_rms_mm=got * 1e3,
            effect_rms_over_sigma=got / sigma,
        )
    # the tracker's Gaussian noise on the exact readings (what measure() does with a noisy
    # tracker, without running the truth's kinematics and effects once more)
    tracker = Tracker(position_m=head, noise=TrackerNoise("gaussian", sigma, 0.0))
    readings = tracker.measure(exact, rng)[:, :, 0]
    model = CalibrationModel(nominal, params)
    parts = {
        "calibration": slice(0, n_cal),
        "test": slice(n_cal, n_cal + n_test),
        "audit": slice(n_cal + n_test, n),
    }
    obs = {k: Observations(commands[sl], readings[sl]) for k, sl in parts.items()}
    orders = {k: order[sl] for k, sl in parts.items()}
    cal, test, audit = obs["calibration"], obs["test"], obs["audit"]
    try:
        # parameters the pose set cannot separate (a redundant error model, e.g. the
        # polisher's) stay at zero; their truth is absorbed by the combinations estimated
        # no outlier rejection: the benchmark's tracker noise is Gaussian without gross
        # outliers, so all a robust fit could reject is the undeclared effect's own readings
        # (a systematic residual of 10 x the noise is no gross outlier), hiding the effect
        # from the diagnosis or ending the case in a refusal before it
        result = identify(model, cal, unidentifiable="fix", robust=False)
        diag = diagnose(
            model,
            cal,
            result,
            sigma,
            order=orders["calibration"],
            tracker_position_m=np.asarray(head),
            test=TestSet(test.commands, test.measured, orders["test"]),
        )
    except CalibError as exc:
        # the pipeline refused the data (e.g. too many outliers): not a right name, and on a
        # geometry-only truth a false alarm; the benchmark counts it so, and says why
        first = str(exc).splitlines()[0]
        return {
            **out,
            "named": f"refused: {type(exc).__name__}",
            "reason": first,
            "audit_rms_after_mm": None,
            "correct": False,
            "first_correct": False,
            "runtime_s": time.perf_counter() - t0,
        }
    # "unexplained" names no effect: the residual exceeds the noise, nothing explains it
    named = "none" if diag.chosen == "unexplained" else diag.chosen
    out.update(
        named=named,
        reason=diag.reason,
        chi2_p_value=diag.chi2_p_value,
        # per coordinate, the geometric fit's residual against the tracker noise
        residual_over_noise=diag.residual_rms_mm / diag.noise_floor_rms_mm,
        absorbed=bool(kind != "none" and diag.chi2_p_value >= ABSORBED_P),
    )
    if diag.test is not None:
        out["test_rms_before_mm"] = diag.test["before"]["rms_mm"]
        out["test_rms_after_mm"] = diag.test["after"]["rms_mm"]
    out.update(_audit(model, result, diag, audit, orders["audit"], np.asarray(head)))
    out["correct"] = is_correct(kind, named)
    out["first_correct"] = is_correct(kind, named.split("+")[0])
    out["runtime_s"] = time.perf_counter() - t0
    return out


def _audit(model, result, diag, audit, audit_order, head) -> dict[str, Any]:
    """3D RMS on the audit poses, before and after adding the named effect: the actuator
    effects through their offsets of the commands (calib.diagnosis.core.effect_offsets, exact
    kinematics), the others through their shifts of the readings
    (calib.diagnosis.core.effect_target_shifts), the geometry correction the diagnosis fitted
    beside them linearly about the geometric fit, as it fitted it (so a correction along a
    direction the pose set hardly sees, in a redundant error model, is not amplified by a
    nonlinear re-solve). A kernel correction ("unexplained: ...") exists only inside the
    diagnosis: not audited."""

    def rms(pred: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((audit.measured - pred) ** 2, axis=-1)))) * 1e3

    values = result.values
    pred = model.predict(values, audit.commands)
    out: dict[str, Any] = {"audit_rms_before_mm": rms(pred.targets)}
    if diag.chosen in ("none", "unexplained"):  # nothing added
        out["audit_rms_after_mm"] = out["audit_rms_before_mm"]
        return out
    if not diag.coefficients:
        out["audit_rms_after_mm"] = None
        out["audit_note"] = f"not audited: {diag.chosen}"
        return out
    timing = dict(time_origin=diag.time_origin, time_unit=diag.time_unit)
    coef = diag.coefficients
    shift = effect_offsets(model, values, audit.commands, audit_order, coef, **timing)
    after = forward_batch(model.mechanism(values), audit.commands + shift, check_stroke=False)
    after = after.targets.copy()
    if diag.geometry_correction is not None:
        jac = model.jacobian(values, pred)[:, result.estimated]
        after = after + (jac @ diag.geometry_correction).reshape(after.shape)
    after = after + effect_target_shifts(
        model, values, audit.commands, audit_order, coef, tracker_position_m=head, **timing
    )
    out["audit_rms_after_mm"] = rms(after)
    return out


# --------------------------------------------------------------------------- the study


def _settings(scenario: Scenario) -> dict[str, Any]:
    return {
        "truth": {
            "distribution": scenario.get("truth.random.distribution", str, "uniform"),
            "translation_mm": scenario.get("truth.random.translation_mm", float),
            "rotation_deg": scenario.get("truth.random.rotation_deg", float, 0.0),
            "encoder_mm": scenario.get("truth.random.encoder_mm", float, 0.0),
            "encoder_deg": scenario.get("truth.random.encoder_deg", float, 0.0),
        },
        "sigma_mm": scenario.get("tracker.sigma_mm", float),
        "tracker_position_mm": scenario.get("tracker.position_mm", list, [1200.0, 0.0, 300.0]),
        "calibration_poses": scenario.get("plan.calibration_poses", int),
        "test_poses": scenario.get("plan.test_poses", int),
        "audit_poses": scenario.get("plan.audit_poses", int),
    }


def cases(scenario: Scenario) -> tuple[list[tuple], list[dict[str, Any]]]:
    """The task arguments of every case, and the cases skipped (with their reason)."""
    machines = [
        {
            "label": scenario.get("machine", str, "machine"),
            "model": scenario.get("model", str),
            "error_model": scenario.get("error_model", str),
            "kinds": scenario.get("benchmark.kinds", list),
        }
    ]
    for i, extra in enumerate(scenario.get("extra_machines", list, [])):
        machines.append(
            {
                "label": extra.get("label", f"machine{i + 1}"),
                "model": extra["model"],
                "error_model": extra["error_model"],
                "kinds": extra.get("kinds", machines[0]["kinds"]),
            }
        )
    multipliers = scenario.get("benchmark.multipliers", list)
    seeds = scenario.get("benchmark.seeds", list)
    none_seeds = scenario.get("benchmark.none_seeds", list)
    base = _settings(scenario)
    args, skipped = [], []
    for mach in machines:
        model_path = str(scenario.resolve(mach["model"], "model"))
        params_path = str(scenario.resolve(mach["error_model"], "error_model"))
        nominal = Mechanism.from_xml(model_path)
        for kind in mach["kinds"]:
            why = not_applicable(kind, nominal)
            if why is not None:
                skipped.append({"machine": mach["label"], "kind": kind, "reason": why})
                continue
            for mult in multipliers:
                for seed in seeds:
                    args.append(
                        (model_path, params_path, mach["label"], kind, float(mult), int(seed), base)
                    )
        for seed in none_seeds:
            args.append((model_path, params_path, mach["label"], "none", 0.0, int(seed), base))
    return args, skipped


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t0 = time.perf_counter()
    args, skipped = cases(scenario)
    progress.step(f"{len(args)} cases ({len(skipped)} kind/machine pairs skipped)")
    results = map_draws(run_case, args, progress, "benchmark cases")
    summary = {
        "scenario": scenario.name,
        "models": sorted({a[2] for a in args}),
        **aggregate(results),
        "goal": {
            "correct_rate_min": 0.8,
            "false_alarm_rate_max": 0.05,
            "heldout_worse_count_max": 0,
            "strong_multiplier": STRONG_MULTIPLIER,
            "absorbed_p": ABSORBED_P,
            "worse_factor": WORSE_FACTOR,
        },
        "accepted_names": {k: list(v) for k, v in ACCEPTED.items()},
        "scaled_argument": {k: v[0] for k, v in SCALED.items()},
        "skipped": skipped,
        "cases": results,
    }
    summary["figures"] = write_figures(out_dir, summary, STRONG_MULTIPLIER)
    titles = {"confusion": "true x named effect", "rate_by_size": "right names by size"}
    for name, file in summary["figures"].items():
        recorder.log_figure(name, out_dir / file, titles[name])
    summary["runtime_s"] = time.perf_counter() - t0
    recorder.log_report(scenario.study, summary)
    return summary
