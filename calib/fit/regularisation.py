"""Weak directions kept at their minimum-norm values, never at held-out cost.

Few poses, one reflector, or a platform seen through one point leave directions of the
parameter space that the readings barely determine: plain least squares puts tens of
millimetres on them with predictions as good as any, a user reads those as the machine's
errors, and the fit creeps along their flat valley without converging. Measured in each
parameter's physical range (1 mm, 0.1 deg: the size an error of its kind has on a built
machine), a direction is *weak* when its standard error, at the residual scale the data
actually show (not an assumed tracker accuracy, which a real machine's unmodelled effects
exceed 10-20 times), exceeds one range.

:func:`choose_subspace` estimates in the well-determined subspace and keeps the weakest
directions at zero, their minimum-norm value (truncated SVD of the range-scaled Jacobian,
the registration always estimated): which directions are kept is chosen by K-fold
cross-validation over poses of the linearised problem at the start, among cut-offs of 10, 3
and 1 ranges and no cut at all. A cut is a candidate only where its cross-validated gain
over plain least squares exceeds its own standard error over the poses (a one-standard-error
rule: on a 6R arm's 20 poses a gain below its scatter chose a cut that was 3.6 % worse on
the 10 held-out poses); among the candidates the strongest whose cross-validated 3D RMS is
within ``TIE`` of the best is kept, so the default is never worse than the plain fit by more
than the data can tell. Only directions worse than one range are ever cut. A plain fit that
creeps without converging is handled apart (:func:`creeping_cuts`).

:func:`choose_prior` does the same cross-validation for a zero-mean Gaussian prior (the
user's ``--prior-std``), so that the output says what it costs or gains on held-out poses.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

# widths of the prior as multiples of the physical ranges, strongest last; None: no prior
SCALES: tuple[float | None, ...] = (None, 100.0, 30.0, 10.0, 3.0, 1.0, 0.3)
TIE = 1e-3  # relative: cross-validated errors this close count as equal
FOLDS = 5


CUTS: tuple[float | None, ...] = (None, 10.0, 3.0, 1.0)  # ranges; None: every direction kept
# the cuts tried, mildest first, when the plain fit crept (:func:`creeping_cuts`): the first
# whose fit converges is kept
CREEP_CUTS: tuple[float, ...] = (100.0, 30.0, 10.0, 3.0, 1.0)


@dataclass(frozen=True)
class SubspaceChoice:
    cut: float | None  # directions with a standard error above this many ranges are kept at 0
    basis: np.ndarray | None  # (k, r) SI: the free parameters = start + basis @ theta
    noise_sigma_m: float  # the data's residual scale per coordinate (linearised plain fit)
    cv_rms_mm: dict[str, float] = field(default_factory=dict)  # label -> 3D RMS held out
    n_weak: int = 0
    folds: int = FOLDS
    reason: str = ""  # why this cut, when not by cross-validation (a creeping plain fit)

    @property
    def n_frozen(self) -> int:
        if self.basis is None:
            return 0
        return self.basis.shape[0] - self.basis.shape[1]

    def as_dict(self) -> dict:
        how = "the plain fit crept" if self.reason else "cross-validation"
        extra = {"chosen_because": self.reason} if self.reason else {}
        return {
            "method": f"truncated SVD in physical ranges, cut chosen by {how}",
            **extra,
            "cut_in_ranges": self.cut,
            "directions_kept_at_zero": self.n_frozen,
            "weak_directions": self.n_weak,
            "noise_sigma_mm_per_coordinate": self.noise_sigma_m * 1e3,
            "cross_validated_rms_mm": dict(self.cv_rms_mm),
            "folds": self.folds,
        }


def cut_label(cut: float | None) -> str:
    return "none" if cut is None else f"cut at {cut:g} ranges"


def _kept(a: np.ndarray, reg: np.ndarray | None, sigma: float, cut: float | None):
    """Directions (k, r) of the range-scaled columns ``a`` the data determine to better than
    ``cut`` ranges (the registration's part projected out); all non-null ones for None."""
    ap = a
    if reg is not None:
        q, _ = np.linalg.qr(reg)
        ap = a - q @ (q.T @ a)
    _, s, vt = np.linalg.svd(ap, full_matrices=False)
    ok = s > (s[0] if s.size else 0.0) * 1e-12
    if cut is not None:
        ok &= s * cut >= sigma
    return vt[ok].T, s


def choose_subspace(
    jac: np.ndarray,
    residual: np.ndarray,
    offsets: np.ndarray,
    ranges: np.ndarray,
    pose_of_row: np.ndarray,
    folds: int = FOLDS,
    cuts: tuple[float | None, ...] = CUTS,
    one_se: bool = True,
    always: np.ndarray | None = None,
    implausible: Callable[..., tuple[str, ...]] | None = None,
) -> SubspaceChoice:
    """The subspace to estimate in, from the plain least-squares fit's linearisation:
    ``residual`` (m,) there and ``jac`` (m, k + r) d residual / d (free parameters, then the
    registration's r); ``offsets`` (k,) the free parameters there minus their start values,
    ``ranges`` (k,) SI, ``pose_of_row`` (m,). The data's residual scale is the plain fit's.
    ``one_se=False`` drops the one-standard-error rule: for a plain fit that did not
    converge, which is no answer for the rule to protect.
    ``always`` (k,) bool: parameters estimated in full beside the subspace, as the
    registration is (those without a known physical size to measure weakness in).
    ``implausible``: the estimates (k,) (SI, from the start values) beyond a plausible size
    (calib.fit.verdict.implausible_estimates). Where the plain fit's are, plain least squares
    is no candidate (a few per cent of cross-validated error does not buy a 2.8 m link
    offset): the mildest cut whose linearised estimates are plausible is taken (else the
    strongest), and the reason says so."""
    if always is not None and np.any(always):
        return _with_always(
            jac, residual, offsets, ranges, pose_of_row, folds, cuts, always, one_se, implausible
        )
    m, k = len(residual), len(ranges)
    sigma = math.sqrt(float(residual @ residual) / max(m - jac.shape[1], 1))
    a = jac[:, :k] * ranges
    reg = jac[:, k:] if jac.shape[1] > k else None
    start = residual - jac[:, :k] @ offsets  # the linearised residual at the start values
    _, s = _kept(a, reg, sigma, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        n_weak = int(np.sum(~(s * 1.0 >= sigma)))
    n_weak += k - len(s)
    poses = np.unique(pose_of_row)
    if n_weak == 0 or len(poses) < 3 or sigma == 0.0:
        return SubspaceChoice(None, None, sigma, {}, n_weak, 0)
    pose_index = np.searchsorted(poses, pose_of_row)
    fold = fold_of_pose(len(poses), folds)[pose_index]
    n_folds = int(fold.max()) + 1
    cv: dict[str, float] = {}
    per_pose: dict[float | None, np.ndarray] = {}  # held-out squared error of each pose
    for cut in cuts:
        sq = np.zeros(m)
        for f in range(n_folds):
            tr, te = fold != f, fold == f
            v, _ = _kept(a[tr], None if reg is None else reg[tr], sigma, cut)
            cols = a @ v if reg is None else np.hstack([a @ v, reg])
            b = np.linalg.lstsq(cols[tr], -start[tr], rcond=None)[0]
            sq[te] = (start[te] + cols[te] @ b) ** 2
        per_pose[cut] = np.bincount(pose_index, weights=sq, minlength=len(poses))
        cv[cut_label(cut)] = math.sqrt(float(sq.sum()) / (m / 3)) * 1e3
    plain = cv[cut_label(None)]
    # one-standard-error rule: a cut is a candidate only where its gain over plain least
    # squares, the mean over poses of the paired difference of their held-out squared
    # errors, exceeds that mean's standard error (what the poses' scatter can tell)
    width = _kept(a, reg, sigma, None)[0].shape[1]
    cut_only = [c for c in cuts if c is not None and _kept(a, reg, sigma, c)[0].shape[1] < width]
    eligible = [None] + [
        c for c in cuts if c is not None and (not one_se or _clear_gain(per_pose, c))
    ]
    best = min(cv[cut_label(c)] for c in eligible)
    chosen: float | None = None
    for cut in eligible:  # the strongest within TIE of the best, never above plain's
        value = cv[cut_label(cut)]
        if value <= best * (1 + TIE) and value <= plain * (1 + TIE):
            chosen = cut
    if chosen is None:
        beyond = () if implausible is None else implausible(offsets)
        if beyond and cut_only:  # no plain answer: the mildest cut that is physical
            chosen, v = _plausible_cut(a, reg, start, ranges, sigma, cut_only, implausible)
            reason = (
                "plain least squares put estimates beyond a plausible size "
                f"({'; '.join(beyond[:3])}) along directions the data barely see; the mildest "
                f"cut whose estimates are plausible ({n_folds}-fold cross-validated 3D RMS "
                f"{cv[cut_label(chosen)]:.4f} mm, plain {plain:.4f} mm)"
            )
            return SubspaceChoice(chosen, ranges[:, None] * v, sigma, cv, n_weak, n_folds, reason)
        return SubspaceChoice(None, None, sigma, cv, n_weak, n_folds)
    v, _ = _kept(a, reg, sigma, chosen)
    return SubspaceChoice(chosen, ranges[:, None] * v, sigma, cv, n_weak, n_folds)


def _plausible_cut(a, reg, start, ranges, sigma, cuts, implausible):
    """(cut, its directions): the mildest of ``cuts`` whose linearised least-squares
    estimates ``implausible`` finds nothing in, else the strongest."""
    ordered = sorted(cuts, reverse=True)
    for cut in ordered:
        v, _ = _kept(a, reg, sigma, cut)
        cols = a @ v if reg is None else np.hstack([a @ v, reg])
        b = np.linalg.lstsq(cols, -start, rcond=None)[0]
        # by any amount: a cut's own standard errors are smaller than the plain fit's
        if not implausible(ranges * (v @ b[: v.shape[1]]), False):
            return cut, v
    return ordered[-1], _kept(a, reg, sigma, ordered[-1])[0]


def creeping_cuts(
    jac: np.ndarray,
    residual: np.ndarray,
    ranges: np.ndarray,
    cuts: tuple[float, ...] = CREEP_CUTS,
) -> list[SubspaceChoice]:
    """The truncations to fit from the start when the plain fit crept along its weak
    directions without converging, mildest first: each cut of ``cuts`` that keeps at least
    one direction at zero. ``jac``, ``residual``, ``ranges`` as for :func:`choose_subspace`,
    at the point the plain fit reached (its residual scale is the data's: creeping moves
    along directions the residual barely feels).

    Cross-validation of the linearisation is no guide there: it is taken where the plain fit
    stopped, tens of millimetres along a curved valley from the start the truncated fit is
    solved from, and on a creeping Stewart platform it ranked the mildest cut worse than
    plain (1.07 against 0.48 mm) where its held-out error was better (0.424 against 0.445).
    The mildest cut whose fit converges is the least change that ends the creeping: only
    directions the data determine worse than ``cut`` physical ranges are kept at zero."""
    m, k = len(residual), len(ranges)
    sigma = math.sqrt(float(residual @ residual) / max(m - jac.shape[1], 1))
    a = jac[:, :k] * ranges
    reg = jac[:, k:] if jac.shape[1] > k else None
    every, s = _kept(a, reg, sigma, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        n_weak = int(np.sum(~(s * 1.0 >= sigma))) + k - len(s)
    out = []
    for cut in cuts:
        v, _ = _kept(a, reg, sigma, cut)
        if v.shape[1] < every.shape[1]:
            reason = (
                "the plain fit did not converge, creeping along directions the data determine "
                f"worse than {cut:g} physical ranges; those are kept at zero from the start"
            )
            out.append(SubspaceChoice(cut, ranges[:, None] * v, sigma, {}, n_weak, 0, reason))
    return out


def _clear_gain(per_pose: dict[float | None, np.ndarray], cut: float) -> bool:
    """Whether ``cut`` lowers the poses' held-out squared errors below plain least squares'
    by more than one standard error of the mean paired difference."""
    diff = per_pose[None] - per_pose[cut]
    if diff.size < 2:
        return False
    gain = float(np.mean(diff))
    return gain > float(np.std(diff, ddof=1)) / math.sqrt(diff.size)


def _with_always(
    jac, residual, offsets, ranges, pose_of_row, folds, cuts, always, one_se, implausible
):
    """:func:`choose_subspace` with the ``always`` columns moved beside the registration's,
    its basis carried back to every free parameter (those columns' rows the identity)."""
    always = np.asarray(always, dtype=bool)
    k = len(ranges)
    rest = np.flatnonzero(~always)

    def inner_implausible(values: np.ndarray, allow_std: bool = True) -> tuple[str, ...]:
        full = np.zeros(k)  # the always-estimated kinds have no plausible size to judge
        full[rest] = values
        return implausible(full, allow_std)

    cols = np.hstack([jac[:, rest], jac[:, :k][:, always], jac[:, k:]])
    # linear in them, the always-estimated columns' start is irrelevant, as the registration's
    inner = choose_subspace(
        cols,
        residual,
        offsets[rest],
        ranges[rest],
        pose_of_row,
        folds,
        cuts,
        one_se=one_se,
        implausible=None if implausible is None else inner_implausible,
    )
    if inner.basis is None:
        return inner
    n_always = int(np.sum(always))
    basis = np.zeros((k, inner.basis.shape[1] + n_always))
    basis[rest, : inner.basis.shape[1]] = inner.basis
    basis[np.flatnonzero(always), inner.basis.shape[1] :] = np.eye(n_always)
    return dataclasses.replace(inner, basis=basis)


@dataclass(frozen=True)
class PriorChoice:
    scale: float | None  # the chosen multiple of the ranges; None: plain least squares
    noise_sigma_m: float  # the data's residual scale per coordinate (plain fit)
    cv_rms_mm: dict[str, float] = field(default_factory=dict)  # label -> 3D RMS held out
    n_weak: int = 0  # directions the plain fit determines worse than their range
    folds: int = FOLDS

    @property
    def label(self) -> str:
        return label(self.scale)

    def as_dict(self) -> dict:
        return {
            "prior_width_in_ranges": self.scale,
            "noise_sigma_mm_per_coordinate": self.noise_sigma_m * 1e3,
            "cross_validated_rms_mm": dict(self.cv_rms_mm),
            "weak_directions": self.n_weak,
            "folds": self.folds,
        }


def label(scale: float | None) -> str:
    return "none" if scale is None else f"{scale:g} x range"


def fold_of_pose(n_poses: int, folds: int = FOLDS) -> np.ndarray:
    """Pose i in fold i mod K: every fold spans the measurement sequence."""
    return np.arange(n_poses) % max(min(folds, n_poses), 2)


def weak_directions(jac: np.ndarray, ranges: np.ndarray, sigma_m: float) -> int:
    """How many directions of the free parameters (``ranges`` (k,) for the first k columns
    of ``jac``; the rest, e.g. the registration's, carry no range) the data determine worse
    than their physical range: a singular direction of the range-scaled Jacobian, mostly in
    the parameters, whose standard error exceeds one range."""
    k = len(ranges)
    if k == 0:
        return 0
    scale = np.ones(jac.shape[1])
    scale[:k] = ranges
    _, s, vt = np.linalg.svd(jac * scale, full_matrices=False)
    with np.errstate(divide="ignore"):
        std = np.where(s > 0, sigma_m / np.where(s > 0, s, 1.0), np.inf)
    in_params = np.linalg.norm(vt[:, :k], axis=1)
    return int(np.sum((std > 1.0) & (in_params > 0.5)))


def choose_prior(
    jac: np.ndarray,
    residual: np.ndarray,
    offsets: np.ndarray,
    ranges: np.ndarray,
    pose_of_row: np.ndarray,
    n_unknown: int,
    folds: int = FOLDS,
    scales: tuple[float | None, ...] = SCALES,
) -> PriorChoice:
    """The prior width for the fit linearised at the plain solution.

    ``jac`` (m, n_unknown): d residual / d unknowns there (the first ``len(ranges)`` columns
    the parameters a prior may act on, the rest the registration's); ``residual`` (m,);
    ``offsets`` (len(ranges),): the parameters' values there relative to the prior's mean;
    ``pose_of_row`` (m,): the pose each row belongs to (rows come in 3s per reading)."""
    m = len(residual)
    k = len(ranges)
    sigma = math.sqrt(float(residual @ residual) / max(m - n_unknown, 1))
    poses = np.unique(pose_of_row)
    n_weak = weak_directions(jac, ranges, sigma)
    if len(poses) < 3 or sigma == 0.0:
        return PriorChoice(None, sigma, {}, n_weak, 0)
    fold = fold_of_pose(len(poses), folds)[np.searchsorted(poses, pose_of_row)]
    n_folds = int(fold.max()) + 1
    cv: dict[str, float] = {}
    for scale in scales:
        w2 = np.zeros(jac.shape[1])
        if scale is not None:
            w2[:k] = (sigma / (ranges * scale)) ** 2
        sse = 0.0
        for f in range(n_folds):
            tr, te = fold != f, fold == f
            a = jac[tr]
            lhs = a.T @ a + np.diag(w2)
            rhs = a.T @ residual[tr]
            rhs[:k] += w2[:k] * offsets
            step = -np.linalg.lstsq(lhs, rhs, rcond=None)[0]
            e = residual[te] + jac[te] @ step
            sse += float(e @ e)
        cv[label(scale)] = math.sqrt(sse / (m / 3)) * 1e3  # 3D RMS per reading, mm
    plain = cv[label(None)]
    best = min(cv.values())
    chosen: float | None = None
    for scale in scales:  # the strongest within TIE of the best, never above plain's
        value = cv[label(scale)]
        if value <= best * (1 + TIE) and value <= plain * (1 + TIE):
            chosen = scale
    return PriorChoice(chosen, sigma, cv, n_weak, n_folds)
