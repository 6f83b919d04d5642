"""A benchmark of the residual diagnosis, not an anecdote: many random truths, one effect each.

A *case* is (machine, twin effect kind or "none", magnitude multiplier, seed). For each case:

1. a random geometric truth (``[truth.random]``, seeded by the case) on the machine;
2. ONE twin effect (``scenarios.machine_setup.EFFECTS``) switched on, its magnitude argument
   (:data:`SCALED`) scaled linearly so that the effect's RMS on the readings, per coordinate
   and noise-free (measured with and without it at a reference magnitude), is ``multiplier``
   times the tracker noise sigma (per coordinate);
3. calibration, test and audit poses measured in one sequence (calibration, then test, then
   audit: the measurement order continues, so time effects keep growing);
4. geometric identification (``calib.identify.identify``) on the calibration set, then
   ``calib.diagnosis.diagnose`` with the test set as the user's test set;
5. scoring: the named effect against the truth kind through :data:`ACCEPTED` (twin kind ->
   the diagnosis's candidate names that are a right answer), and the 3D RMS error on the audit
   poses (which neither the fit nor the diagnosis saw) before and after adding the named
   effect; *worse* is after > before * 1.02.

The aggregate is a confusion table (true kind -> named), the rate of right names over cases
with multiplier >= 2, the false-alarm rate over "none" cases (anything named but "none") and
the count of cases whose audit error got worse. The cases run through
``scenarios.sweep_draws.map_draws`` (in-process, or on Ray when asked).

The twin's effects and the diagnosis's candidates are separate code with separate names: the
diagnosis never imports the twin. Only this benchmark (the truth side) knows both.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.diagnosis import TestSet, diagnose, effect_offsets
from calib.exceptions import CalibError
from calib.identify import bind_dataset, identify
from calib.model import CalibrationModel
from scenarios.config import Scenario
from scenarios.machine_setup import EFFECTS
from scenarios.progress import Progress
from scenarios.recording import Recorder
from scenarios.sweep_draws import map_draws
from scenarios.truth_draw import TruthSpec, draw_truth
from scenarios.twin_datasets import measured_dataset
from twin.kinematics_batch import forward_batch
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.parameter_file import load_parameter_set
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

WORSE_FACTOR = 1.02  # audit RMS after > before * this: the named effect made it worse
STRONG_MULTIPLIER = 2.0  # correct_rate counts the cases at or above this many noise sigmas

# Which diagnosis names are a right answer for each twin kind, and why. "none" is right only
# where the twin's effect is (nearly) one the geometric error model itself absorbs.
ACCEPTED: dict[str, tuple[str, ...]] = {
    # the screw's periodic travel error at its pitch: the free-pitch "lead_error" candidate
    "lead_error": ("lead_error",),
    # the same screw error with a 2nd harmonic: its 1st harmonic is still "lead_error"
    "lead_error_harmonic": ("lead_error",),
    # legs growing in time: a command-proportional growth in time ("thermal_growth"); on a
    # hexapod whose legs have similar lengths, an offset drift in time ("zero_drift") is
    # nearly the same shape, so both name the physics right (heat makes the machine drift)
    "thermal_warmup": ("thermal_growth", "zero_drift"),
    "thermal_growth": ("thermal_growth", "zero_drift"),
    # a scale error of each actuator's measuring system
    "actuator_gain": ("gain_error",),
    # each reflector off its nominal site in the tool frame
    "reflector_offset": ("reflector_offsets",),
    # lost motion on reversal, at the actuator (backlash) or in a revolute drive
    "backlash": ("backlash",),
    "joint_backlash": ("backlash",),
    # deflection under the machine's own weight and a payload
    "gravity_compliance": ("gravity_compliance",),
    "joint_compliance": ("gravity_compliance",),
    # a wrong air compensation is a scale of every distance from the head: "tracker_scale";
    # with a short tracker distance most of it is a scale of the base frame that geometry
    # absorbs, so "none" is an acceptable answer too
    "tracker_air_temperature": ("tracker_scale", "none"),
    "none": ("none",),
}

# How each kind is sized: (argument, reference value, fixed arguments, "linear" or
# "inverse"). The argument is scaled linearly from the reference value so the effect's
# noise-free RMS on the readings hits the target ("inverse": the argument is a stiffness,
# the effect scales with its inverse, the compliance).
SCALED: dict[str, tuple[str, float, dict[str, Any], str]] = {
    "lead_error": ("amplitude_m", 5e-6, {"pitch_m": 5e-3}, "linear"),
    # amplitudes [a, 0.4 a] of the once- and twice-per-revolution harmonics: a scales both
    "lead_error_harmonic": ("amplitude_m", 10e-6, {"pitch_m": 4e-3}, "linear"),
    "thermal_warmup": (
        "delta_K",
        3.0,
        {"tau_s": 1200.0, "seconds_per_pose": 30.0, "bodies": "leg*,limb*"},
        "linear",
    ),
    "thermal_growth": ("rate_K_per_pose", 0.02, {}, "linear"),
    "actuator_gain": ("magnitude_ppm", 200.0, {}, "linear"),
    "reflector_offset": ("magnitude_m", 30e-6, {}, "linear"),
    "backlash": ("play_m", 10e-6, {}, "linear"),
    "joint_backlash": ("play_rad", 30 * np.pi / 648000, {}, "linear"),
    # stiffness of prismatic (2e7 N/m) and revolute (2e5 N m/rad) drives, both / ratio
    "gravity_compliance": ("stiffness_N_per_m", 2e7, {}, "inverse"),
    "joint_compliance": ("stiffness_Nm_per_rad", 5e4, {"payload_kg": 5.0}, "inverse"),
    # hall minus set temperature (K); the set temperature stays 20 C
    "tracker_air_temperature": ("hall_minus_set_K", 3.0, {}, "linear"),
}
SEEDED = ("lead_error_harmonic", "actuator_gain", "reflector_offset")  # draw from a seed


def effect_for(kind: str, value: float, seed: int):
    """The twin effect ``kind`` with its scaled argument at ``value``."""
    arg, _, fixed, _ = SCALED[kind]
    args = dict(fixed)
    if kind == "lead_error_harmonic":
        args["amplitudes_m"] = (value, 0.4 * value)
    elif kind == "tracker_air_temperature":
        args.update(set_C=20.0, hall_C=20.0 + value)
    elif kind == "gravity_compliance":
        args.update(stiffness_N_per_m=value, stiffness_Nm_per_rad=value * 1e-2)
    else:
        args[arg] = value
    if kind in SEEDED:
        args["seed"] = seed
    return EFFECTS[kind](**args)


def not_applicable(kind: str, mech: Mechanism) -> str | None:
    """Why ``kind`` does not apply to this machine (None when it does)."""
    slide = np.asarray(mech.actuator_is_slide)
    if kind in ("joint_backlash", "joint_compliance") and slide.all():
        return "acts on revolute actuators; this machine's actuators are all prismatic"
    if kind in ("lead_error", "lead_error_harmonic", "thermal_growth") and not slide.any():
        return "acts on prismatic (screw) actuators; this machine has none"
    if kind in ("gravity_compliance", "joint_compliance") and mech.masses_defaulted:
        return "the model's masses are defaulted: a gravity effect on them is meaningless"
    if kind == "reflector_offset" and mech.n_targets < 2:
        return "one reflector: its offset is the tool offset, which geometry absorbs"
    return None


def _rms_coord(a: np.ndarray, b: np.ndarray) -> float:
    """RMS per coordinate of a - b (3D RMS / sqrt(3))."""
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def _noise_free(truth, commands, head, effects, order):
    tracker = Tracker(position_m=head, noise=TrackerNoise("gaussian", 0.0, 0.0))
    return measure(truth, commands, tracker, np.random.default_rng(0), effects=effects, order=order)


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
    rng = np.random.default_rng(seed)
    nominal = Mechanism.from_xml(model_path)
    params = load_parameter_set(params_path, nominal.model)
    spec = TruthSpec(**settings["truth"])
    truth_values = draw_truth(params, spec, rng)
    truth = nominal.with_model(params.inject(nominal.model, truth_values))
    sigma = settings["sigma_mm"] * 1e-3
    head = tuple(v * 1e-3 for v in settings["tracker_position_mm"])
    n_cal, n_test, n_audit = (
        settings["calibration_poses"],
        settings["test_poses"],
        settings["audit_poses"],
    )
    n = n_cal + n_test + n_audit
    poses, commands = random_poses(nominal, n, rng)
    order = np.arange(n)  # one sequence: calibration, then test, then audit
    out: dict[str, Any] = {
        "machine": machine,
        "kind": kind,
        "multiplier": multiplier,
        "seed": seed,
    }
    effects = []
    if kind != "none":
        arg, ref, _, how = SCALED[kind]
        plain = _noise_free(truth, commands, head, [], order).readings
        ref_rms = _rms_coord(
            _noise_free(truth, commands, head, [effect_for(kind, ref, seed)], order).readings, plain
        )
        if not ref_rms > 0:
            return {**out, "skipped": f"the effect at {arg} = {ref:g} does not change the readings"}
        ratio = multiplier * sigma / ref_rms
        value = ref * ratio if how == "linear" else ref / ratio
        try:
            effects = [effect_for(kind, value, seed)]
        except ValueError as exc:  # e.g. an air temperature no hall has: not a case
            return {**out, "skipped": f"{arg} = {value:.4g} is out of the effect's range: {exc}"}
        got = _rms_coord(_noise_free(truth, commands, head, effects, order).readings, plain)
        out.update(
            scaled_argument=arg,
            argument_value=value,
            effect_rms_mm=got * 1e3,
            effect_rms_over_sigma=got / sigma,
        )
    tracker = Tracker(position_m=head, noise=TrackerNoise("gaussian", sigma, 0.0))
    m = measure(truth, commands, tracker, rng, effects=effects, order=order)
    model = CalibrationModel(nominal, params)
    parts = {
        "calibration": slice(0, n_cal),
        "test": slice(n_cal, n_cal + n_test),
        "audit": slice(n_cal + n_test, n),
    }
    obs, orders = {}, {}
    for name, sl in parts.items():
        ds = measured_dataset(truth, commands[sl], poses[sl], name, tracker, rng)
        ds = type(ds)(**{**ds.__dict__, "readings": m.readings[sl], "order": order[sl]})
        obs[name], orders[name] = bind_dataset(nominal, ds), order[sl]
    cal, test, audit = obs["calibration"], obs["test"], obs["audit"]
    try:
        # parameters the pose set cannot separate (a redundant error model, e.g. the
        # polisher's) stay at zero; their truth is absorbed by the combinations estimated
        result = identify(model, cal, unidentifiable="fix")
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
    named = diag.chosen
    out.update(named=named, reason=diag.reason, chi2_p_value=diag.chi2_p_value)
    if diag.test is not None:
        out["test_rms_before_mm"] = diag.test["before"]["rms_mm"]
        out["test_rms_after_mm"] = diag.test["after"]["rms_mm"]
    out.update(_audit(model, result, diag, audit, orders["audit"], np.asarray(head)))
    out["correct"] = is_correct(kind, named)
    out["first_correct"] = is_correct(kind, named.split("+")[0])
    out["runtime_s"] = time.perf_counter() - t0
    return out


# named effects whose audit prediction this benchmark forms: actuator offsets
# (calib.diagnosis.effect_offsets), geometry beyond the error model (reflector offsets, joint
# axis tilts: injected with the model's own values) and the tracker scale (about the head). A
# kernel correction ("unexplained: ...") is defined only inside the diagnosis: not audited.
_GEOMETRIC = ("reflector_offsets", "joint_axis_errors")


def _audit(model, result, diag, audit, audit_order, head) -> dict[str, Any]:
    """3D RMS on the audit poses, before and after adding the named effect."""
    from calib.diagnosis import default_candidates
    from calib.diagnosis_context import extra_parameters
    from twin.parameters import ParameterSet

    def rms(pred: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((audit.measured - pred) ** 2, axis=-1)))) * 1e3

    before = model.predict(result.values, audit.commands).targets
    out: dict[str, Any] = {"audit_rms_before_mm": rms(before)}
    if diag.chosen == "none":
        out["audit_rms_after_mm"] = out["audit_rms_before_mm"]
        return out
    mech = model.nominal
    lib = {
        c.name: c
        for c in default_candidates(
            mech.actuator_names, mech.actuator_is_slide, mech.masses_defaulted
        )
    }
    names = list(diag.coefficients)
    missing = [
        k
        for k in names
        if k not in ("tracker_scale", *_GEOMETRIC) and (k not in lib or lib[k].offsets is None)
    ]
    if not names or missing:
        out["audit_rms_after_mm"] = None
        out["audit_note"] = f"not audited: {', '.join(missing) or diag.chosen}"
        return out
    # the diagnosis fits its corrections linearly about the geometric fit (its geometric
    # columns, its effect columns): predict the audit poses the same way, so a correction
    # along a direction the pose set hardly sees (a redundant error model) is not amplified
    # by a nonlinear re-solve
    values = result.values
    pred = model.predict(values, audit.commands)
    shift = effect_offsets(
        model,
        values,
        audit.commands,
        audit_order,
        diag.coefficients,
        time_origin=diag.time_origin,
        time_unit=diag.time_unit,
    )
    after = forward_batch(model.mechanism(values), audit.commands + shift, check_stroke=False)
    after = after.targets.copy()
    extra = extra_parameters(model) if any(k in _GEOMETRIC for k in names) else {}
    plist, delta = list(model.params.parameters), np.zeros(len(values))
    if diag.geometry_correction is not None:
        delta[result.estimated] = diag.geometry_correction
    deltas = [delta]
    for k in names:
        if k in _GEOMETRIC:
            plist += extra[k]
            deltas.append(np.asarray(diag.coefficients[k], dtype=float))
    full = CalibrationModel(mech, ParameterSet(plist, mech.model))
    x0 = np.concatenate([values, np.zeros(len(plist) - len(values))])
    jac = full.jacobian(x0, pred)
    after = after + (jac @ np.concatenate(deltas)).reshape(after.shape)
    scale = float(diag.coefficients.get("tracker_scale", [0.0])[0])
    after = after + scale * (after - head)  # a scale of the readings about the head
    out["audit_rms_after_mm"] = rms(after)
    return out


def is_correct(kind: str, named: str) -> bool:
    """Every effect named is one :data:`ACCEPTED` allows for ``kind`` ("a+b" names two)."""
    parts = named.split("+")
    return all(p in ACCEPTED[kind] for p in parts)


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


def aggregate(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The confusion table and the rates of the benchmark's goal."""
    done = [r for r in results if "named" in r]
    confusion: dict[str, dict[str, int]] = {}
    for r in done:
        row = confusion.setdefault(r["kind"], {})
        row[r["named"]] = row.get(r["named"], 0) + 1
    strong = [r for r in done if r["kind"] != "none" and r["multiplier"] >= STRONG_MULTIPLIER]
    nones = [r for r in done if r["kind"] == "none"]
    audited = [r for r in done if r.get("audit_rms_after_mm") is not None]
    worse = [
        r for r in audited if r["audit_rms_after_mm"] > r["audit_rms_before_mm"] * WORSE_FACTOR
    ]
    by_mult: dict[str, dict[str, float]] = {}
    for mult in sorted({r["multiplier"] for r in done if r["kind"] != "none"}):
        rs = [r for r in done if r["kind"] != "none" and r["multiplier"] == mult]
        by_mult[f"{mult:g}"] = {"n": len(rs), "correct_rate": _rate(rs, "correct")}
    by_kind = {
        k: {"n": len(rs), "correct_rate": _rate(rs, "correct")}
        for k in sorted({r["kind"] for r in strong})
        for rs in [[r for r in strong if r["kind"] == k]]
    }
    return {
        "n_cases": len(done),
        "confusion": confusion,
        "correct_rate": _rate(strong, "correct"),
        # the first (strongest) name right, whatever else was named beside it
        "first_name_correct_rate": _rate(strong, "first_correct"),
        "n_correct_rate_cases": len(strong),
        "false_alarm_rate": (
            sum(r["named"] != "none" for r in nones) / len(nones) if nones else None
        ),
        "n_none_cases": len(nones),
        "heldout_worse_count": len(worse),
        "skipped_cases": [
            {k: r[k] for k in ("machine", "kind", "multiplier", "seed", "skipped")}
            for r in results
            if "named" not in r
        ],
        "n_audited": len(audited),
        "not_audited": [
            {k: r[k] for k in ("machine", "kind", "multiplier", "seed", "named")}
            for r in done
            if r.get("audit_rms_after_mm") is None
        ],
        "heldout_worse_cases": [
            {k: r[k] for k in ("machine", "kind", "multiplier", "seed", "named")} for r in worse
        ],
        "correct_rate_by_multiplier": by_mult,
        "correct_rate_by_kind": by_kind,
    }


def _rate(rs: list[dict[str, Any]], key: str) -> float | None:
    return sum(bool(r[key]) for r in rs) / len(rs) if rs else None


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
            "worse_factor": WORSE_FACTOR,
        },
        "accepted_names": {k: list(v) for k, v in ACCEPTED.items()},
        "scaled_argument": {k: v[0] for k, v in SCALED.items()},
        "skipped": skipped,
        "cases": results,
        "runtime_s": time.perf_counter() - t0,
    }
    recorder.log_report(scenario.study, summary)
    return summary
