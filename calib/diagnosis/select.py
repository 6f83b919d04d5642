"""Which effects to name: forward selection judged on held-out poses only.

Every candidate is first evaluated alone beside the geometry (nested cross-validation,
calib.diagnosis.fit); one that physics forbids (calib.diagnosis.verdict.refusal) is refused.
Then effects are added one at a time, the best of those that pass, while one passes: it must
lower the held-out RMS by ``min_gain`` in every fold scheme with a one-sided Wilcoxon
p < ``alpha`` on the per-pose improvement, lower the user's test-set error when there is one
without raising its largest error, and (in a combination) stay physical. When the residual
passes the noise test, an effect must also lower the held-out mean square by more than noise
moves it (``noise_ms``): a verdict consistent with its own test says "none" otherwise. A
candidate that does not help alone is not tried in a combination.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from calib.diagnosis.candidate import Candidate
from calib.diagnosis.context import Context
from calib.diagnosis.fit import Evaluation, evaluate, shared_bases
from calib.diagnosis.problem import SCHEMES, Problem
from calib.diagnosis.verdict import improvement, refusal
from common.worker_processes import Progress, map_in_order, worker_count

# (evaluation, its candidates) -> the test set's 3D error per reading (m), None without one
TestErrors = Callable[[Evaluation, list[Candidate]], "np.ndarray | None"]


@dataclass
class Selection:
    base: Evaluation  # geometry only
    singles: dict[str, Evaluation]  # each candidate alone
    refused: dict[str, str]  # candidate -> why physics forbids its fit
    chosen: list[Candidate] = field(default_factory=list)
    current: Evaluation | None = None  # geometry + the chosen effects
    why_not: dict[str, str] = field(default_factory=dict)  # alone, why it did not pass


def select_effects(
    prob: Problem,
    ctx: Context,
    fold_sets: dict,
    cands: list[Candidate],
    n_rows: int,
    alpha: float,
    min_gain: float,
    max_effects: int,
    test_errors: TestErrors,
    noise_ms: float | None = None,
) -> Selection:
    """``noise_ms``: the held-out mean square per row (m^2) that an effect must gain beyond
    when the residual is what the noise explains (None: the residual exceeds the noise)."""
    workers = worker_count(prob.r.size, len(cands))
    if workers > 1:  # computed once here (side by side), read by every worker
        shared_bases(prob, ctx, fold_sets, workers)
    base = evaluate(prob, ctx, fold_sets, [], None, n_rows)
    singles, refused = {}, {}

    def alone(i: int) -> tuple[Evaluation, str]:
        ev = evaluate(prob, ctx, fold_sets, [cands[i]], None, n_rows)
        return ev, refusal(prob, ctx, [cands[i]], ev)

    progress = Progress("candidates", len(cands), workers)
    for c, (ev, why) in zip(cands, map_in_order(alone, len(cands), workers), strict=True):
        singles[c.name] = ev
        if why:
            refused[c.name] = why
        progress.step(c.name)
    helps = {
        k: all(v.heldout_rms_mm(s) < base.heldout_rms_mm(s) for s in SCHEMES)
        for k, v in singles.items()
    }

    def passes(cur: Evaluation, cur_c: list[Candidate], new: Evaluation, new_c: list[Candidate]):
        for s in SCHEMES:
            gain, pv = improvement(cur.heldout[s], new.heldout[s])
            if gain < min_gain or pv >= alpha:
                return False, f"{s} folds: held-out RMS {1 - gain:.3g} x, Wilcoxon p = {pv:.2g}"
        if noise_ms is not None:
            gain_ms = float(np.sum(cur.heldout[SCHEMES[0]])) - float(
                np.sum(new.heldout[SCHEMES[0]])
            )
            gain_ms /= n_rows
            if gain_ms < noise_ms:
                return False, (
                    "the residual passes the noise test and the held-out gain "
                    f"({max(gain_ms, 0.0) ** 0.5 * 1e3:.3g} mm RMS) is within what noise gives "
                    f"({noise_ms**0.5 * 1e3:.3g} mm)"
                )
        before, after = test_errors(cur, cur_c), test_errors(new, new_c)
        if before is not None and after is not None:
            rms_b, rms_a = _rms(before), _rms(after)
            if not rms_a < rms_b:
                return False, f"the test set's error rises ({rms_b:.4g} -> {rms_a:.4g})"
            if float(np.max(after)) > float(np.max(before)):
                return False, (
                    f"the test set's largest error rises ({np.max(before) * 1e3:.4g} -> "
                    f"{np.max(after) * 1e3:.4g} mm)"
                )
        return True, ""

    sel = Selection(base, singles, refused, current=base)
    while len(sel.chosen) < max_effects:
        trials = []
        tried = [
            c
            for c in cands
            if c not in sel.chosen
            and c.name not in refused
            and (not sel.chosen or helps[c.name])  # no help alone: not tried in a combination
        ]
        if sel.chosen:
            chosen, current = list(sel.chosen), sel.current

            def combined(i: int, chosen=chosen, current=current, tried=tried) -> Evaluation:
                return evaluate(prob, ctx, fold_sets, [*chosen, tried[i]], current, n_rows)

            many = min(workers, len(tried))
            progress = Progress(
                f"combinations with {'+'.join(c.name for c in chosen)}", len(tried), many
            )
            evs = []
            for c, ev in zip(tried, map_in_order(combined, len(tried), many), strict=True):
                evs.append(ev)
                progress.step(c.name)
        else:
            evs = [singles[c.name] for c in tried]
        for c, ev in zip(tried, evs, strict=True):
            new_c = [*sel.chosen, c]
            ok, why = passes(sel.current, sel.chosen, ev, new_c)
            if ok and sel.chosen:
                bad = refusal(prob, ctx, new_c, ev)
                ok, why = (False, f"refused: {bad}") if bad else (True, "")
            if ok:
                trials.append((ev.heldout_rms_mm(), c, ev))
            elif not sel.chosen:
                sel.why_not[c.name] = why
        if not trials:
            break
        _, best, ev = min(trials, key=lambda t: t[0])
        sel.chosen.append(best)
        sel.current = ev
    return sel


def _rms(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(errors) ** 2)))
