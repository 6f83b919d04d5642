"""Judging a candidate: held-out improvement, physical refusals, what is reported.

* ``improvement``: the relative drop of the held-out RMS and the one-sided Wilcoxon p of the
  per-pose held-out improvement (a few poses much better cannot hide many slightly worse).
* ``refusal``: a sign physics fixes (play, compliance >= 0) that the unconstrained fit
  violates by more than two standard errors: the candidate is refused, not reported.
* ``effect_parameters``: values in display units with standard errors, the shape too; a
  parameter the data do not determine (redundant with the geometry or another effect
  parameter) gets no value, ``determined: false`` and why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.diagnosis.candidate import Candidate
from calib.diagnosis.context import Context
from calib.diagnosis.fit import Evaluation, uncertainty, undetermined
from calib.diagnosis.problem import SCHEMES, Problem

REFUSE_Z = 2.0
LOOSE = (
    "not determined by these data: its effect is one of the geometry's or the other effect "
    "parameters' (identify --with fixes it as redundant)"
)


@dataclass(frozen=True)
class TestSet:
    """Poses that took no part in the fit: commands (N, A) SI, base-frame readings (N, T, 3),
    and when they were measured (order, or seconds), on the calibration's time axis."""

    __test__ = False  # not a pytest class

    commands: np.ndarray
    measured: np.ndarray
    order: np.ndarray | None = None
    time_s: np.ndarray | None = None


@dataclass(frozen=True)
class CandidateScore:
    name: str
    n_parameters: int
    heldout_rms_mm: float  # per coordinate, pooled over the fold schemes
    bic: float
    theta: np.ndarray  # effect parameters (SI), from all poses
    geometry: np.ndarray  # correction of the estimated geometric parameters (SI)
    heldout_blocked_mm: float = float("nan")
    heldout_random_mm: float = float("nan")
    test_rms_mm: float | None = None  # 3D per reading on the test set, if given
    shape: float = float("nan")  # SI (pitch m, time constant, harmonic, payload kg)
    refused: str = ""


def improvement(before: np.ndarray, after: np.ndarray) -> tuple[float, float]:
    """(1 - RMS_after / RMS_before, one-sided Wilcoxon p that per-pose SSE fell)."""
    gain = 1.0 - float(np.sqrt(np.sum(after) / max(np.sum(before), 1e-300)))
    d = np.asarray(before) - np.asarray(after)
    d = d[d != 0]
    if d.size < 5:
        return gain, 1.0
    from scipy import stats  # lazy: scipy.stats costs about 1 s at import

    return gain, float(stats.wilcoxon(d, alternative="greater").pvalue)


def refusal(prob: Problem, ctx: Context, cands: list[Candidate], ev: Evaluation) -> str:
    """Why a fit is physically impossible ('' if it is not)."""
    u = uncertainty(prob, ctx, cands, ev)
    start, bad = 0, []
    for c, k in zip(cands, ev.sizes, strict=True):
        for j in range(k):
            if c.nonnegative and c.nonnegative[j]:
                v, s = u.theta[start + j], u.std[start + j]
                if v < -REFUSE_Z * s:
                    f = c.factors[j]
                    bad.append(f"{c.parameters[j]} = {v * f:.3g} +- {s * f:.2g} {c.units[j]}")
        start += k
    if not bad:
        return ""
    what = next(c.physics for c in cands if c.nonnegative)
    return f"{what}: " + ", ".join(bad)


def effect_parameters(
    prob: Problem,
    ctx: Context,
    cands: list[Candidate],
    ev: Evaluation,
    rigid: dict[str, np.ndarray] | None = None,
) -> dict[str, dict]:
    """Per effect: parameter -> value, std, unit (display units); the shape likewise.

    ``rigid`` (candidate name -> (k, 6)): what a rigid motion does to that candidate's
    parameters, where the data see them only up to one (reflector offsets beside the
    platform's or flange's own errors): its values are then the rigid-motion-free part
    (the offsets of the reflectors relative to each other), its std errors propagated, and a
    ``note`` says so."""
    u = uncertainty(prob, ctx, cands, ev)
    loose = undetermined(prob, ctx, cands, ev)
    out, start = {}, 0
    for i, (c, k) in enumerate(zip(cands, ev.sizes, strict=True)):
        theta = ev.fit.theta[start : start + k]
        std = u.std[start : start + k]
        span = None if rigid is None else rigid.get(c.name)
        note = ""
        if span is not None and len(span) == k:
            proj = np.eye(k) - span @ np.linalg.pinv(span)
            theta = proj @ theta
            block = u.cov[start : start + k, start : start + k] if u.cov is not None else None
            if block is not None and np.all(np.isfinite(block)):
                std = np.sqrt(np.clip(np.diag(proj @ block @ proj.T), 0, None))
            note = (
                "up to a rigid motion of the reflector set: the data fix the reflectors' "
                "offsets relative to each other, not a common motion of all of them (the "
                "tool's own errors take that); shown without it"
            )
        entry: dict = {}
        for j in range(k):
            f = c.factors[j]
            entry[c.parameters[j]] = {
                "value": float(theta[j] * f),
                "std": float(std[j] * f) if np.isfinite(std[j]) else None,
                "unit": c.units[j],
            }
            # no value where any would fit the data as well (a rigid motion's share of the
            # reflectors' offsets is already taken out above and said in the note)
            if loose[start + j] and not note:
                entry[c.parameters[j]].update(value=None, std=None, determined=False, why=LOOSE)
        if c.shaped:
            s, sd = ev.shapes[i], u.shape_std[i]
            entry[c.shape_name] = {
                "value": float(s * c.shape_factor) if np.isfinite(s) else "inf",
                "std": None if not np.isfinite(sd) else float(sd * c.shape_factor),
                "unit": c.shape_unit,
            }
        if note:
            entry["note"] = {"value": note, "std": None, "unit": ""}
        out[c.name] = entry
        start += k
    return out


def test_errors(tr, tctx: Context, cands: list[Candidate], ev: Evaluation) -> np.ndarray:
    """3D error per test reading (metres) after the model of ``ev``."""
    e = tr.r - tr.geo @ ev.fit.beta
    if cands:
        xs = [c.design(tctx, s) for c, s in zip(cands, ev.shapes, strict=True)]
        e = e - np.concatenate(xs, axis=2) @ ev.fit.theta
    return np.linalg.norm(e.reshape(len(e), -1, 3), axis=2)


def score_of(
    name: str,
    ev: Evaluation,
    prob: Problem,
    ctx: Context,
    cands: list[Candidate],
    test_rms: float | None,
    refused: str = "",
) -> CandidateScore:
    xs = [c.design(ctx, s) for c, s in zip(cands, ev.shapes, strict=True)]
    e = prob.r - prob.geo @ ev.fit.beta
    if xs:
        e = e - np.concatenate(xs, axis=2) @ ev.fit.theta
    rss = float(np.sum(e**2))
    n, p = ev.n_rows, prob.geo.shape[2]
    k = int(sum(ev.sizes)) + sum(c.shaped for c in cands)
    bic = n * np.log(max(rss, 1e-300) / n) + (p + k) * np.log(n)
    return CandidateScore(
        name=name,
        n_parameters=k,
        heldout_rms_mm=ev.heldout_rms_mm(),
        bic=float(bic),
        theta=ev.fit.theta,
        geometry=ev.fit.beta,
        heldout_blocked_mm=ev.heldout_rms_mm(SCHEMES[0]),
        heldout_random_mm=ev.heldout_rms_mm(SCHEMES[1]),
        test_rms_mm=None if test_rms is None else test_rms * 1e3,
        shape=float(ev.shapes[0]) if ev.shapes else float("nan"),
        refused=refused,
    )


def lowering(base: Evaluation, singles: dict[str, Evaluation]) -> list[tuple[str, float]]:
    """The candidates whose held-out RMS is below geometry alone's in every fold scheme, with
    their pooled held-out RMS (mm per coordinate), best first."""
    out = [
        (name, ev.heldout_rms_mm())
        for name, ev in singles.items()
        if all(ev.heldout_rms_mm(s) < base.heldout_rms_mm(s) for s in SCHEMES)
    ]
    return sorted(out, key=lambda item: item[1])


def physical_sentence(base: Evaluation, singles: dict[str, Evaluation], min_gain: float) -> str:
    """Whether physical candidates lower the held-out error, in the numbers of the table."""
    lower = lowering(base, singles)
    if not lower:
        return "no physical candidate lowers the held-out error"
    shown = ", ".join(f"{n} {v:.4g} mm" for n, v in lower[:4]) + (" ..." if len(lower) > 4 else "")
    return (
        f"{len(lower)} physical candidate(s) lower the held-out error (geometry alone "
        f"{base.heldout_rms_mm():.4g} mm; {shown}) but none by the {100 * min_gain:g} % in "
        "every fold scheme, significant pose by pose and no worse on the test poses, that "
        "naming one requires"
    )
