"""Residual diagnosis after geometric calibration: is there more than noise, and what is it?

1. Noise: the residual against the tracker noise (chi-square with n - p degrees of freedom);
   the noise comes from repeat readings when the data has them (calib.diagnosis_noise).
2. Candidates (calib.diagnosis_candidates): generic physics with free shape (gain, screw
   lead of any pitch 2-20 mm, encoder eccentricity, backlash, thermal growth and drift with a
   scanned time constant, compliance under gravity with a scanned payload, reflector offsets,
   joint-axis errors, tracker drift and scale); nothing of the truth twin's effects.
3. An honest choice (calib.diagnosis_fit, calib.diagnosis_verdict): each candidate is fitted
   beside the geometric columns and judged by nested cross-validation, outer folds blocked by
   measurement order and random, and on the user's test set when given. An effect is named
   only when it lowers the held-out error by a clear margin in every scheme (and on the test
   set); a fit that physics forbids (a negative play or compliance) is refused. When nothing
   physical explains a residual that a kernel correction over some pose variable does
   explain on held-out poses, the answer is "unexplained: correlated with <variable>".

The naming depends on held-out errors only, never on the sigma: the chi-square is reported,
and the verdict is the same for any plausible sigma.

Only the readings the identification kept enter (``IdentificationResult.rejected`` lists the
gross outliers it left out): an outlier is not an effect.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from calib.diagnosis_candidates import (
    GRAVITY_SKIPPED,
    NO_SHAPE,
    Candidate,
    default_candidates,
    library,
)
from calib.diagnosis_context import Context, actuator_offsets, build_context
from calib.diagnosis_fit import SCHEMES, Evaluation, Problem, evaluate, fold_labels
from calib.diagnosis_noise import NoiseLevel, check_against_residual, chi_square_p, noise_level
from calib.diagnosis_unexplained import features, kernel_correction, kernel_heldout
from calib.diagnosis_verdict import (
    CandidateScore,
    TestSet,
    effect_parameters,
    improvement,
    refusal,
    score_of,
    test_errors,
)
from calib.identify import IdentificationResult, Observations, _one_blas_thread
from calib.model import CalibrationModel
from calib.position_error import stats_mm
from twin.sensitivity import target_jacobian

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


def actuator_jacobians(model: CalibrationModel, values: np.ndarray, qpos: np.ndarray):
    """Per pose, d(targets)/d(actuator offsets), (N, T*3, A)."""
    mech = model.mechanism(values)
    offsets = actuator_offsets(model)
    zero = np.zeros(len(offsets))
    return np.array([target_jacobian(mech, offsets, zero, q) for q in qpos])


def kept_rows(result: IdentificationResult, shape: tuple[int, int]) -> np.ndarray:
    """(N, T*3) boolean: the residual rows of the readings ``result`` kept (not rejected)."""
    keep = np.ones(shape, dtype=bool)
    for rej in result.rejected:
        keep[rej.pose_index, rej.target_index] = False
    return np.repeat(keep, 3, axis=1)


def _time(order, time_s, n) -> tuple[np.ndarray, str]:
    if time_s is not None:
        return np.asarray(time_s, dtype=float), "s"
    return (np.arange(n) if order is None else np.asarray(order)).astype(float), "pose"


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
) -> Diagnosis:
    """Diagnose the residual of a geometric calibration ``result`` on ``obs``.

    ``sigma_m``: the typed tracker noise per coordinate (None: from the repeats, given as
    ``repeat_std_m`` over ``n_repeats``). ``order`` / ``time_s``: when each pose was measured.
    ``test``: poses that took no part in the fit (commands, base-frame readings, their order):
    an effect must lower their error too. ``min_gain``: the relative drop of the held-out RMS
    an effect must bring in every fold scheme; ``alpha``: the one-sided Wilcoxon level of the
    per-pose held-out improvement."""
    with _one_blas_thread():
        return _diagnose(
            model,
            obs,
            result,
            sigma_m,
            order,
            candidates,
            folds,
            alpha,
            min_gain,
            tracker_position_m,
            time_s,
            repeat_std_m,
            n_repeats,
            test,
            max_effects,
        )


def _diagnose(
    model,
    obs,
    result,
    sigma_m,
    order,
    candidates,
    folds,
    alpha,
    min_gain,
    tracker_position_m,
    time_s,
    repeat_std_m,
    n_repeats,
    test,
    max_effects,
) -> Diagnosis:
    n_poses = len(obs.commands)
    time, unit = _time(order, time_s, n_poses)
    t0 = float(np.min(time))
    values = result.values
    pred = model.predict(values, obs.commands)
    keep = kept_rows(result, obs.measured.shape[:2])  # (N, T*3)
    r = (obs.measured - pred.targets).reshape(n_poses, -1) * keep
    n = int(keep.sum())
    p = int(result.estimated.sum())
    noise = noise_level(sigma_m, repeat_std_m, n_repeats)
    sum_sq = float(np.sum(r**2))
    p_value = chi_square_p(sum_sq, noise.sigma_m, n - p)
    excess = p_value < alpha
    geo = (
        model.jacobian(values, pred)[:, result.estimated].reshape(n_poses, -1, p) * keep[:, :, None]
    )
    head = None if tracker_position_m is None else np.asarray(tracker_position_m, dtype=float)
    ctx = build_context(
        model, values, obs.commands, time - t0, unit, pred.qpos, pred.targets, head=head, rows=keep
    )
    notes = list(noise.notes)
    if candidates is None:
        cands = library(ctx, model.nominal.masses_defaulted)
        if model.nominal.masses_defaulted:
            notes.append(GRAVITY_SKIPPED)
    else:
        cands = list(candidates)
    prob = Problem(r, geo)
    fold_sets = {s: fold_labels(ctx.time, folds, s) for s in SCHEMES}
    tctx = _test_context(model, values, test, t0, unit, ctx, head) if test is not None else None
    tr = None if tctx is None else _test_residual(model, values, result, test, tctx)

    base = evaluate(prob, ctx, fold_sets, [], None, n)
    singles, refused = {}, {}
    for c in cands:
        ev = evaluate(prob, ctx, fold_sets, [c], None, n)
        singles[c.name] = ev
        why = refusal(prob, ctx, [c], ev)
        if why:
            refused[c.name] = why
            notes.append(f"{c.name} refused: {why}")
    test_of = {}
    helps = {
        k: all(v.heldout_rms_mm(s) < base.heldout_rms_mm(s) for s in SCHEMES)
        for k, v in singles.items()
    }

    def test_rms(ev: Evaluation, cs: list[Candidate]) -> float | None:
        if tctx is None:
            return None
        key = ev.names
        if key not in test_of:
            test_of[key] = test_errors(tr, tctx, cs, ev)
        return float(np.sqrt(np.mean(test_of[key] ** 2)))

    def passes(cur: Evaluation, cur_c: list[Candidate], new: Evaluation, new_c: list[Candidate]):
        for s in SCHEMES:
            gain, pv = improvement(cur.heldout[s], new.heldout[s])
            if gain < min_gain or pv >= alpha:
                return False, f"{s} folds: held-out RMS {1 - gain:.3g} x, Wilcoxon p = {pv:.2g}"
        if tctx is not None:
            before, after = test_rms(cur, cur_c), test_rms(new, new_c)
            if not after < before:
                return False, f"the test set's error rises ({before:.4g} -> {after:.4g})"
        return True, ""

    chosen: list[Candidate] = []
    current = base
    why_not: dict[str, str] = {}
    while len(chosen) < max_effects:
        trials = []
        for c in cands:
            if c in chosen or c.name in refused:
                continue
            if chosen and not helps[c.name]:  # no help alone: not tried in a combination
                continue
            ev = (
                singles[c.name]
                if not chosen
                else evaluate(prob, ctx, fold_sets, [*chosen, c], current, n)
            )
            ok, why = passes(current, chosen, ev, [*chosen, c])
            if ok and chosen:
                bad = refusal(prob, ctx, [*chosen, c], ev)
                ok, why = (False, f"refused: {bad}") if bad else (True, "")
            if ok:
                trials.append((ev.heldout_rms_mm(), c, ev))
            elif not chosen:
                why_not[c.name] = why
        if not trials:
            break
        _, best, ev = min(trials, key=lambda t: t[0])
        chosen.append(best)
        current = ev
    scores = {"none": score_of("none", base, prob, ctx, [], test_rms(base, []))}
    for c in cands:
        scores[c.name] = score_of(
            c.name,
            singles[c.name],
            prob,
            ctx,
            [c],
            test_rms(singles[c.name], [c]),
            refused.get(c.name, ""),
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
    )
    from calib.diagnosis_unexplained import structure_detail

    common["structure_detail"] = structure_detail(r, keep, ctx)
    before_stats = None if tr is None else _stats(tr.r)
    if chosen:
        ev = current
        names = [c.name for c in chosen]
        floor = ev.heldout_rms_mm() * 1e-3 / np.sqrt(1.0)
        notes += list(check_against_residual(noise, floor))
        test_block = None
        if tctx is not None:
            test_block = {
                "before": before_stats,
                "after": _stats(_test_after(tr, tctx, chosen, ev)),
            }
        return Diagnosis(
            **common,
            chosen="+".join(names),
            reason=(
                f"{' and '.join(names)} {'lower' if len(names) > 1 else 'lowers'} the held-out "
                f"error from {_schemes(base)} to {_schemes(ev)} mm"
                + (
                    ""
                    if tctx is None
                    else f"; test RMS {test_block['before']['rms_mm']:.4g} -> "
                    f"{test_block['after']['rms_mm']:.4g} mm (3D)"
                )
            ),
            geometry_correction=ev.fit.beta,
            coefficients=_coefficients(chosen, ev),
            effect_parameters=effect_parameters(prob, ctx, chosen, ev),
            notes=tuple(notes),
            test=test_block,
            plot=_plot_data(ctx, r, keep, chosen, ev, prob),
        )
    # nothing physical: is there structure a kernel correction explains on held-out poses?
    feats = features(ctx)
    kern = {}
    for group, x in feats.items():
        kern[group] = kernel_heldout(prob, x, fold_sets, keep)
    best_group, best_gain = None, 0.0
    for group, held in kern.items():
        ok = True
        gains = []
        for s in SCHEMES:
            gain, pv = improvement(base.heldout[s], held[s])
            gains.append(gain)
            ok &= gain >= min_gain and pv < alpha
        test_block = None
        if ok and tctx is not None:
            after = _kernel_test(prob, feats[group], keep, tr, tctx, group)
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
            after = _kernel_test(prob, feats[best_group], keep, tr, tctx, best_group)
            test_block = {"before": before_stats, "after": _stats(after)}
        held = common["heldout"][f"kernel({best_group})"]
        return Diagnosis(
            **common,
            chosen=f"unexplained: correlated with {best_group}",
            reason=(
                "no physical candidate lowers the held-out error, but a kernel correction "
                f"over {best_group} does ({_schemes(base)} -> "
                + ", ".join(f"{s} {held[s]:.4g}" for s in SCHEMES)
                + " mm)"
            ),
            notes=tuple(notes),
            test=test_block,
            plot=_plot_unexplained(ctx, r, keep, best_group, feats[best_group]),
        )
    test_block = None if tctx is None else {"before": before_stats, "after": before_stats}
    if not excess:
        reason = "the residual is what the tracker noise explains"
    else:
        reason = (
            "the residual exceeds the noise (chi-square) but no candidate, and no kernel "
            "correction, lowers the held-out error: nothing is named"
        )
    if why_not:
        best = min(singles.values(), key=lambda e: e.heldout_rms_mm())
        if best.names and best.names[0] in why_not:
            reason += f" (closest: {best.names[0]}, {why_not[best.names[0]]})"
    return Diagnosis(**common, reason=reason, notes=tuple(notes), test=test_block)


def _schemes(ev: Evaluation) -> str:
    return " / ".join(f"{ev.heldout_rms_mm(s):.4g}" for s in SCHEMES) + f" ({'/'.join(SCHEMES)})"


def _stats(e: np.ndarray) -> dict[str, float]:
    """3D position error per reading (target at pose) of a residual (N, T*3)."""
    norms = np.linalg.norm(e.reshape(len(e), -1, 3), axis=2)
    s = stats_mm(norms).as_dict()
    return {"rms_mm": s["rms_mm"], "mean_mm": s["mean_mm"], "max_mm": s["max_mm"], "n": s["n"]}


def _coefficients(chosen: list[Candidate], ev: Evaluation) -> dict[str, np.ndarray]:
    out, start = {}, 0
    for c, k, s in zip(chosen, ev.sizes, ev.shapes, strict=True):
        theta = ev.fit.theta[start : start + k]
        out[c.name] = np.concatenate([theta, [s]]) if c.shaped else theta
        start += k
    return out


@dataclass(frozen=True)
class _TestResidual:
    r: np.ndarray  # (Nt, R) before
    geo: np.ndarray  # (Nt, R, p)


def _test_context(model, values, test: TestSet, t0, unit, ctx: Context, head) -> Context:
    t = test.time_s if test.time_s is not None else test.order
    n = len(test.commands)
    t = np.arange(n) + ctx.time.max() + t0 + 1 if t is None else np.asarray(t, float)
    seq = np.argsort(ctx.time)
    previous = ctx.commands[seq[-1]] if np.min(t - t0) > ctx.time.max() else None
    return build_context(model, values, test.commands, t - t0, unit, previous=previous, head=head)


def _test_residual(model, values, result, test: TestSet, tctx: Context) -> _TestResidual:
    n = len(test.commands)
    r = (np.asarray(test.measured) - tctx.targets).reshape(n, -1)
    from calib.model import Prediction

    jac = model.jacobian(values, Prediction(tctx.targets, _qpos(model, values, test.commands)))
    p = int(result.estimated.sum())
    return _TestResidual(r, jac[:, result.estimated].reshape(n, -1, p))


def _qpos(model, values, commands):
    return model.predict(values, commands).qpos


def _test_after(tr: _TestResidual, tctx: Context, cands: list[Candidate], ev: Evaluation):
    e = tr.r - tr.geo @ ev.fit.beta
    if cands:
        xs = [c.design(tctx, s) for c, s in zip(cands, ev.shapes, strict=True)]
        e = e - np.concatenate(xs, axis=2) @ ev.fit.theta
    return e


def _kernel_test(prob, x_cal, keep, tr: _TestResidual, tctx: Context, group: str):
    x_test = features(tctx)[group]
    both = Problem(np.vstack([prob.r, tr.r]), np.vstack([prob.geo, tr.geo]))
    n = len(prob.r)
    train = np.zeros(len(both.r), bool)
    train[:n] = True
    k = np.vstack([keep, np.ones(tr.r.shape, bool)])
    corrected, _ = kernel_correction(both, np.vstack([x_cal, x_test]), train, k)
    return corrected(~train)


def _plot_data(ctx, r, keep, chosen, ev, prob) -> dict:
    """The per-pose residual before and after against the variable the first effect uses."""
    c = chosen[0]
    var, label = ctx.time, f"time ({ctx.time_unit})"
    if c.offsets is not None:
        k0 = ev.sizes[0]
        theta = ev.fit.theta[:k0]
        off = np.einsum("nak,k->na", c.offsets(ctx, ev.shapes[0]), theta)
        a = int(np.argmax(np.sqrt(np.mean(off**2, axis=0))))
        name = ctx.actuator_names[a]
        if c.explains in ("command", "joint angle"):
            var, label = ctx.commands[:, a], f"{name} command (SI)"
        elif c.explains == "command modulo pitch":
            var, label = (
                np.mod(ctx.commands[:, a], ev.shapes[0]),
                f"{name} command modulo pitch (m)",
            )
        elif c.explains == "gravity load":
            var, label = ctx.gravity.own[:, a], f"{name} gravity load (N or N m)"
        elif c.explains == "approach direction":
            var, label = -c.offsets(ctx, NO_SHAPE)[:, a, a], f"{name} approach direction"
    elif c.explains == "tool orientation":
        turn = features(ctx)["tool orientation"]
        i = int(np.argmax(np.ptp(turn, axis=0)))
        var, label = turn[:, i], f"tool rotation about {'xyz'[i]} (rad)"
    xs = [cc.design(ctx, s) for cc, s in zip(chosen, ev.shapes, strict=True)]
    after = r - prob.geo @ ev.fit.beta - np.concatenate(xs, axis=2) @ ev.fit.theta
    return _plot_dict(label, var, r, after, keep)


def _plot_unexplained(ctx, r, keep, group, x) -> dict:
    i = int(np.argmax(np.ptp(x, axis=0) / np.maximum(np.abs(x).max(axis=0), 1e-300)))
    return _plot_dict(f"{group} [{i}]", x[:, i], r, None, keep)


def _plot_dict(label, var, before, after, keep) -> dict:
    def size(e):
        cnt = np.maximum(keep.sum(axis=1), 1)
        return (np.sqrt(np.sum(np.where(keep, e, 0) ** 2, axis=1) / cnt) * 1e3).tolist()

    return {
        "variable": label,
        "x": np.asarray(var, float).tolist(),
        "before_mm": size(before),
        "after_mm": None if after is None else size(after),
    }


def effect_offsets(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    chosen: dict[str, np.ndarray],
    candidates: list[Candidate] | None = None,
    time_origin: float = 0.0,
    time_unit: str = "pose",
) -> np.ndarray:
    """Actuator offsets (N, A) that the chosen effects predict for these commands (in
    measurement ``order``, or seconds for ``time_unit='s'``). Effects that are not actuator
    offsets (geometry, tracker) contribute nothing here."""
    mech = model.nominal
    lib = {
        c.name: c
        for c in candidates
        or default_candidates(mech.actuator_names, mech.actuator_is_slide, mech.masses_defaulted)
    }
    out = np.zeros_like(np.asarray(commands, dtype=float))
    acting = [n for n in chosen if n in lib and lib[n].offsets is not None]
    if not acting:
        return out
    need_gravity = any(n == "gravity_compliance" for n in acting)
    ctx = build_context(
        model,
        values,
        commands,
        np.asarray(order, dtype=float) - time_origin,
        time_unit,
        full=False,
        gravity=need_gravity,
    )
    for name in acting:
        c, coef = lib[name], np.asarray(chosen[name], dtype=float)
        theta, shape = (coef[:-1], float(coef[-1])) if c.shaped else (coef, NO_SHAPE)
        out += np.einsum("nak,k->na", c.offsets(ctx, shape), theta)
    return out


def residual_structure(
    r: np.ndarray,
    targets: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    keep: np.ndarray | None = None,
) -> dict[str, float]:
    """Spearman rank correlation of each pose's residual size with where and when it was
    measured: tool position x, y, z (space), mean actuator value (actuator coordinates) and
    measurement order (time). Values near 0 mean no structure along that direction.

    ``keep`` (same shape as ``r``) marks the rows to use; a pose with none is left out."""
    keep = np.ones(r.shape, dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    count = keep.sum(axis=1)
    some = count > 0
    size = np.sqrt(np.sum(np.where(keep, r, 0.0) ** 2, axis=1)[some] / count[some])
    centre = targets.mean(axis=1)[some]
    commands = np.asarray(commands)[some]
    order = np.asarray(order)[some]
    probes = {
        "x": centre[:, 0],
        "y": centre[:, 1],
        "z": centre[:, 2],
        "mean_actuator": commands.mean(axis=1),
        "order": np.asarray(order, dtype=float),
    }
    out = {}
    for name, v in probes.items():
        rho = stats.spearmanr(size, v).statistic if np.ptp(v) > 0 else 0.0
        out[name] = float(np.nan_to_num(rho))
    return out
