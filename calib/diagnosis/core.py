"""Residual diagnosis after geometric calibration: is there more than noise, and what is it?

1. Noise: the residual against the tracker noise (chi-square with n - p degrees of freedom);
   the noise comes from repeat readings when the data has them (calib.diagnosis.noise).
2. Candidates (calib.diagnosis.candidates): generic physics with free shape (gain, screw
   lead of any pitch 2-20 mm, encoder eccentricity, backlash, thermal growth and drift with a
   scanned time constant, compliance under gravity with a scanned payload, reflector offsets,
   joint-axis errors, tracker drift and scale); nothing of the truth twin's effects.
3. An honest choice (calib.diagnosis.fit, calib.diagnosis.verdict): each candidate is fitted
   beside the geometric columns and judged by nested cross-validation, outer folds blocked by
   measurement order and random, and on the user's test set when given. An effect is named
   only when it lowers the held-out error by a clear margin in every scheme (and on the test
   set); a fit that physics forbids (a negative play or compliance) is refused. When nothing
   physical explains a residual that a kernel correction over some pose variable does
   explain on held-out poses, the answer is "unexplained: correlated with <variable>".

The naming depends on held-out errors, and on the sigma in one place only: when the residual
passes the chi-square noise test, an effect must also lower the held-out mean square by more
than the noise moves it (three standard deviations of the mean square of pure noise), so that
the verdict is consistent with its own test ("none" otherwise). Nothing named where the
residual exceeds the noise is "unexplained", with the structure the residual shows.

Modules: the candidates (calib.diagnosis.candidates) and what they see of each pose
(calib.diagnosis.context, calib.diagnosis.gravity); fitting and nested cross-validation
(calib.diagnosis.fit); the forward selection (calib.diagnosis.select) and its judgement
(calib.diagnosis.verdict); the test set (calib.diagnosis.testset); structure no candidate
explains (calib.diagnosis.unexplained); the figure's data (calib.diagnosis.plot); named
effects applied to other poses (calib.diagnosis.apply: ``effect_offsets`` for the actuator
effects, ``effect_target_shifts`` for those acting on the readings).

Only the readings the identification kept enter (``IdentificationResult.rejected`` lists the
gross outliers it left out): an outlier is not an effect.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.analysis.rank_structure import describe
from calib.diagnosis.apply import (
    actuator_jacobians,
    effect_offsets,
    effect_target_shifts,
    kept_rows,
)
from calib.diagnosis.candidate import Candidate
from calib.diagnosis.candidates import (
    GRAVITY_PAYLOAD_ONLY,
    GRAVITY_SKIPPED,
    default_candidates,
    library,
)
from calib.diagnosis.context import build_context, reflector_span
from calib.diagnosis.fit import Evaluation
from calib.diagnosis.noise import NoiseLevel, check_against_residual, chi_square_p, noise_level
from calib.diagnosis.plot import plot_data, plot_unexplained
from calib.diagnosis.problem import SCHEMES, Problem, fold_labels
from calib.diagnosis.select import select_effects
from calib.diagnosis.testset import (
    kernel_test,
    rigid_columns,
    stats_3d,
    test_after,
    test_context,
    test_residual,
)
from calib.diagnosis.unexplained import (
    features,
    kernel_heldout,
    residual_structure,
    structure_detail,
)
from calib.diagnosis.verdict import (
    CandidateScore,
    TestSet,
    effect_parameters,
    improvement,
    physical_sentence,
    score_of,
    test_errors,
)
from calib.fit.identification import IdentificationResult
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations
from twin.kinematics.structure import on_one_blas_thread

__all__ = [
    "GRAVITY_SKIPPED",
    "Candidate",
    "CandidateScore",
    "Diagnosis",
    "TestSet",
    "actuator_jacobians",
    "default_candidates",
    "diagnose",
    "effect_offsets",
    "effect_target_shifts",
    "kept_rows",
    "residual_structure",
]


@dataclass(frozen=True)
class Diagnosis:
    residual_rms_mm: float
    noise_floor_rms_mm: float
    chi2_p_value: float
    excess: bool
    scores: dict[str, CandidateScore] = field(default_factory=dict)
    chosen: str = "none"
    reason: str = ""
    # effect parameters, SI: the linear ones, then the shape (pitch m, time constant, ...)
    coefficients: dict[str, np.ndarray] = field(default_factory=dict)
    structure: dict[str, float] = field(default_factory=dict)  # rank correlations
    geometry_correction: np.ndarray | None = None  # for the estimated geometric parameters
    notes: tuple[str, ...] = ()  # candidates skipped or refused, and why
    effect_parameters: dict[str, dict] = field(default_factory=dict)  # units and std errors
    heldout: dict[str, dict[str, float]] = field(default_factory=dict)  # model -> scheme -> mm
    test: dict[str, dict[str, float]] | None = None  # before / after: rms, mean, max (mm)
    noise: NoiseLevel | None = None
    structure_detail: dict[str, dict[str, float]] = field(default_factory=dict)
    plot: dict | None = None  # the residual against the variable that explains it
    time_origin: float = 0.0
    time_unit: str = "pose"
    # what the named effects (or the geometry alone) leave, per pose, for a residual
    # correction after them (calib.correction): see _leftover
    leftover: dict | None = None


def _time(order, time_s, n) -> tuple[np.ndarray, str]:
    if time_s is not None:
        return np.asarray(time_s, dtype=float), "s"
    return (np.arange(n) if order is None else np.asarray(order)).astype(float), "pose"


@on_one_blas_thread
def diagnose(
    model: CalibrationModel,
    obs: Observations,
    result: IdentificationResult,
    sigma_m: float | None,
    order: np.ndarray | None = None,
    candidates: list[Candidate] | None = None,
    folds: int = 5,
    alpha: float = 0.01,
    min_gain: float = 0.05,
    tracker_position_m: np.ndarray | None = None,
    time_s: np.ndarray | None = None,
    repeat_std_m: np.ndarray | None = None,
    n_repeats: int = 1,
    test: TestSet | None = None,
    max_effects: int = 3,
    registration: bool = False,
    sigma_source: str = "typed",
) -> Diagnosis:
    """Diagnose the residual of a geometric calibration ``result`` on ``obs``.

    ``sigma_m``: the typed tracker noise per coordinate (None: from the repeats, given as
    ``repeat_std_m`` over ``n_repeats``), ``sigma_source`` where it came from. ``order`` /
    ``time_s``: when each pose was measured.
    ``test``: poses that took no part in the fit (commands, base-frame readings, their order):
    an effect must lower their error too. ``min_gain``: the relative drop of the held-out RMS
    an effect must bring in every fold scheme; ``alpha``: the one-sided Wilcoxon level of the
    per-pose held-out improvement. ``registration``: the readings were carried into the base
    frame by a registration fitted with the geometry (tracker-frame data): its rigid motion
    is refitted beside the geometry, or an effect's fit could not undo what the
    registration absorbed of it."""
    n_poses = len(obs.commands)
    time, unit = _time(order, time_s, n_poses)
    t0 = float(np.min(time))
    values = result.values
    pred = model.predict(values, obs.commands)
    keep = kept_rows(result, obs.measured.shape[:2])  # (N, T*3)
    r = (obs.measured - pred.targets).reshape(n_poses, -1) * keep
    n = int(keep.sum())
    p = int(result.estimated.sum())
    noise = noise_level(sigma_m, repeat_std_m, n_repeats, sigma_source)
    sum_sq = float(np.sum(r**2))
    p_value = chi_square_p(sum_sq, noise.sigma_m, n - p)
    geo = model.jacobian(values, pred)[:, result.estimated].reshape(n_poses, -1, p)
    if registration:
        geo = np.concatenate([geo, rigid_columns(pred.targets)], axis=2)
    geo = geo * keep[:, :, None]
    head = None if tracker_position_m is None else np.asarray(tracker_position_m, dtype=float)
    ctx = build_context(
        model, values, obs.commands, time - t0, unit, pred.qpos, pred.targets, head=head, rows=keep
    )
    notes = list(noise.notes)
    if candidates is None:
        cands = library(ctx, model.nominal.masses_defaulted)
        if model.nominal.masses_defaulted:
            notes.append(GRAVITY_PAYLOAD_ONLY)
    else:
        cands = list(candidates)
    prob = Problem(r, geo)
    fold_sets = {s: fold_labels(ctx.time, folds, s) for s in SCHEMES}
    tctx = tr = None
    if test is not None:
        tctx = test_context(model, values, test, t0, unit, ctx, head)
        tr = test_residual(model, values, result.estimated, test, tctx, registration)
    test_of: dict[tuple[str, ...], np.ndarray] = {}

    def test_errs(ev: Evaluation, cs: list[Candidate]) -> np.ndarray | None:
        if tctx is None:
            return None
        if ev.names not in test_of:
            test_of[ev.names] = test_errors(tr, tctx, cs, ev)
        return test_of[ev.names]

    def test_rms(ev: Evaluation, cs: list[Candidate]) -> float | None:
        e = test_errs(ev, cs)
        return None if e is None else float(np.sqrt(np.mean(e**2)))

    excess = p_value < alpha
    # within noise: a held-out mean-square gain below 3 standard deviations of the mean square
    # of n rows of pure noise (chi-square: sigma^2 sqrt(2 / n))
    noise_ms = None if excess else 3.0 * noise.sigma_m**2 * np.sqrt(2.0 / max(n, 1))
    sel = select_effects(
        prob, ctx, fold_sets, cands, n, alpha, min_gain, max_effects, test_errs, noise_ms
    )
    notes += [f"{k} refused: {why}" for k, why in sel.refused.items()]
    base, singles = sel.base, sel.singles
    before_stats = None if tr is None else stats_3d(tr.r)
    # geometry alone on the test poses is the geometric calibration itself: "test before"
    none_test = None if before_stats is None else before_stats["rms_mm"] * 1e-3
    scores = {"none": score_of("none", base, prob, ctx, [], none_test)}
    for c in cands:
        ev = singles[c.name]
        scores[c.name] = score_of(
            c.name, ev, prob, ctx, [c], test_rms(ev, [c]), sel.refused.get(c.name, "")
        )
    common = dict(
        residual_rms_mm=float(np.sqrt(sum_sq / n)) * 1e3,
        noise_floor_rms_mm=noise.sigma_m * 1e3,
        chi2_p_value=p_value,
        excess=excess,
        scores=scores,
        structure=residual_structure(r, pred.targets, obs.commands, time, keep),
        noise=noise,
        time_origin=t0,
        time_unit=unit,
        heldout={
            "none": {s: base.heldout_rms_mm(s) for s in SCHEMES},
            **{k: {s: v.heldout_rms_mm(s) for s in SCHEMES} for k, v in singles.items()},
        },
        structure_detail=structure_detail(r, keep, ctx),
    )
    if sel.chosen:
        ev, chosen = sel.current, sel.chosen
        names = [c.name for c in chosen]
        notes += list(check_against_residual(noise, ev.heldout_rms_mm() * 1e-3))
        test_block = None
        if tctx is not None:
            test_block = {
                "before": before_stats,
                "after": stats_3d(test_after(tr, tctx, chosen, ev)),
            }
        reason = (
            f"{' and '.join(names)} {'lower' if len(names) > 1 else 'lowers'} the held-out "
            f"error from {_schemes(base)} to {_schemes(ev)} mm"
        )
        if test_block is not None:
            reason += (
                f"; test RMS {test_block['before']['rms_mm']:.4g} -> "
                f"{test_block['after']['rms_mm']:.4g} mm (3D) by the linearised fit"
            )
        return Diagnosis(
            **common,
            leftover=_leftover(prob, ctx, ev, chosen, tr, tctx, fold_sets, keep),
            chosen="+".join(names),
            reason=reason,
            geometry_correction=ev.fit.beta[:p],
            coefficients=_coefficients(chosen, ev),
            effect_parameters=effect_parameters(prob, ctx, chosen, ev, reflector_span(model)),
            notes=tuple(notes),
            test=test_block,
            plot=plot_data(ctx, r, keep, chosen, ev, prob),
        )
    # nothing physical: is there structure a kernel correction explains on held-out poses?
    feats = features(ctx)
    kern = kernel_heldout(prob, feats, fold_sets, keep)
    best_group, best_gain = None, 0.0
    for group, held in kern.items():
        gains, ok = [], True
        for s in SCHEMES:
            gain, pv = improvement(base.heldout[s], held[s])
            gains.append(gain)
            ok &= gain >= min_gain and pv < alpha
        if ok and tctx is not None:
            after = kernel_test(prob, feats[group], keep, tr, tctx, group)
            ok = float(np.sqrt(np.mean(after**2))) < float(np.sqrt(np.mean(tr.r**2)))
        if ok and min(gains) > best_gain:
            best_group, best_gain = group, min(gains)
    for group, held in kern.items():
        common["heldout"][f"kernel({group})"] = {
            s: float(np.sqrt(np.sum(held[s]) / n)) * 1e3 for s in SCHEMES
        }
    if best_group is not None:
        test_block = None
        if tctx is not None:
            after = kernel_test(prob, feats[best_group], keep, tr, tctx, best_group)
            test_block = {"before": before_stats, "after": stats_3d(after)}
        held = common["heldout"][f"kernel({best_group})"]
        return Diagnosis(
            **common,
            leftover=_leftover(prob, ctx, base, [], tr, tctx, fold_sets, keep),
            chosen=f"unexplained: correlated with {best_group}",
            reason=(
                f"{physical_sentence(base, singles, min_gain)}, but a kernel correction "
                f"over {best_group} does ({_schemes(base)} -> "
                + ", ".join(f"{s} {held[s]:.4g}" for s in SCHEMES)
                + " mm)"
            ),
            notes=tuple(notes),
            test=test_block,
            plot=plot_unexplained(ctx, r, keep, best_group, feats[best_group]),
        )
    test_block = None if tctx is None else {"before": before_stats, "after": before_stats}
    chosen = "none"
    if not common["excess"]:
        reason = "the residual is what the tracker noise explains"
    else:
        chosen = "unexplained"
        reason = (
            f"the residual exceeds the noise (chi-square p = {p_value:.3g}); "
            f"{physical_sentence(base, singles, min_gain)}, and no kernel correction lowers "
            "it; " + describe(common["structure_detail"])
        )
    if sel.why_not:
        best = min(singles.values(), key=lambda e: e.heldout_rms_mm())
        if best.names and best.names[0] in sel.why_not:
            reason += f" (closest: {best.names[0]}, {sel.why_not[best.names[0]]})"
    return Diagnosis(
        **common,
        leftover=_leftover(prob, ctx, base, [], tr, tctx, fold_sets, keep),
        chosen=chosen,
        reason=reason,
        notes=tuple(notes),
        test=test_block,
    )


def _leftover(prob, ctx, ev, chosen, tr, tctx, fold_sets, keep) -> dict:
    """The residual (N, R) the geometry correction and the named effects of ``ev`` leave on
    the calibration poses (and the test poses' when given), with each pose's commands, tool
    position (mean of its targets), fold of the blocked scheme and whether all its rows
    were kept: what a residual correction after them is fitted to and judged on."""
    e = prob.r - prob.geo @ ev.fit.beta
    if chosen:
        xs = [c.design(ctx, s) for c, s in zip(chosen, ev.shapes, strict=True)]
        e = e - np.concatenate(xs, axis=2) @ ev.fit.theta
    out = {
        "residual": e * keep,
        "commands": ctx.commands,
        "position": ctx.targets.mean(axis=1),
        "labels": fold_sets["blocked"],
        "complete": keep.all(axis=1),
        "named": bool(chosen),
    }
    if tctx is not None:
        out["test_residual"] = test_after(tr, tctx, chosen, ev)
        out["test_commands"] = tctx.commands
        out["test_position"] = tctx.targets.mean(axis=1)
        out["test_before"] = tr.r
    return out


def _schemes(ev: Evaluation) -> str:
    return " / ".join(f"{ev.heldout_rms_mm(s):.4g}" for s in SCHEMES) + f" ({'/'.join(SCHEMES)})"


def _coefficients(chosen: list[Candidate], ev: Evaluation) -> dict[str, np.ndarray]:
    out, start = {}, 0
    for c, k, s in zip(chosen, ev.sizes, ev.shapes, strict=True):
        theta = ev.fit.theta[start : start + k]
        out[c.name] = np.concatenate([theta, [s]]) if c.shaped else theta
        start += k
    return out
