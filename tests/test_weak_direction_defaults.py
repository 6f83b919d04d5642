"""Defaults for weak directions and for a fit that creeps: the one-standard-error rule of the
cross-validated truncation, and Levenberg-Marquardt ending when its cost has settled."""

from __future__ import annotations

import math

import numpy as np

from calib.estimators.levenberg_marquardt import LMOptions, levenberg_marquardt
from calib.fit.regularisation import choose_subspace, cut_label, fold_of_pose


def _problem(seed: int, n_poses: int, weak_truth: float, k: int = 8, sigma: float = 1e-4):
    """A linear calibration of ``k`` parameters (ranges 1) from ``n_poses`` 3D readings with
    noise ``sigma``: standard errors from 0.01 to 100 ranges; the truth's component along each
    direction worse than one range is ``weak_truth`` of that direction's standard error.
    Returns choose_subspace's inputs at the plain least-squares fit."""
    rng = np.random.default_rng(seed)
    m = 3 * n_poses
    u, _ = np.linalg.qr(rng.normal(size=(m, k)))
    v, _ = np.linalg.qr(rng.normal(size=(k, k)))
    s = np.geomspace(1e-2, 1e-6, k)
    jac = (u * s) @ v.T
    coef = np.where(sigma / s > 1.0, weak_truth * sigma / s, 1.0)
    truth = v @ (coef * rng.choice([-1, 1], k))
    start = -jac @ truth + sigma * rng.normal(size=m)  # the residual at the start values
    plain = np.linalg.lstsq(jac, -start, rcond=None)[0]
    return jac, start + jac @ plain, plain, np.ones(k), np.repeat(np.arange(n_poses), 3)


def _gain_in_standard_errors(jac, residual, plain, pose, cut: float) -> float:
    """The cut's mean gain over plain least squares in the poses' held-out squared errors,
    in standard errors of that mean, computed here from the definition (K-fold over poses,
    the cut's directions from each training fold's SVD at the data's residual scale)."""
    m, k = jac.shape
    sigma = math.sqrt(float(residual @ residual) / (m - k))
    start = residual - jac @ plain
    fold = fold_of_pose(pose.max() + 1)[pose]
    errors = {}
    for c in (None, cut):
        sq = np.zeros(m)
        for f in np.unique(fold):
            tr, te = fold != f, fold == f
            _, s, vt = np.linalg.svd(jac[tr], full_matrices=False)
            keep = s > s[0] * 1e-12 if c is None else s * c >= sigma
            cols = jac @ vt[keep].T
            b = np.linalg.lstsq(cols[tr], -start[tr], rcond=None)[0]
            sq[te] = (start[te] + cols[te] @ b) ** 2
        errors[c] = np.bincount(pose, weights=sq)
    diff = errors[None] - errors[cut]
    return float(diff.mean() / (diff.std(ddof=1) / math.sqrt(diff.size)))


def test_plain_is_kept_where_truncations_gain_is_within_its_scatter():
    args = _problem(seed=2, n_poses=20, weak_truth=1.5)
    choice = choose_subspace(*args)
    cv = choice.cv_rms_mm
    # the cut at 10 ranges is 2.8 % better cross-validated: the strongest cut within TIE of
    # the best, the old rule's choice; its gain is a third of its standard error
    assert cv[cut_label(10.0)] < 0.98 * cv["none"]
    assert min(cv.values()) == cv[cut_label(10.0)]
    assert 0 < _gain_in_standard_errors(*args[:3], args[4], 10.0) < 1.0
    assert choice.cut is None and choice.basis is None


def test_truncation_is_kept_where_its_gain_is_clear():
    args = _problem(seed=1, n_poses=20, weak_truth=0.0)  # weak directions truly at zero
    choice = choose_subspace(*args)
    assert choice.cut == 3.0 and choice.basis is not None
    assert choice.cv_rms_mm[cut_label(3.0)] == min(choice.cv_rms_mm.values())
    assert _gain_in_standard_errors(*args[:3], args[4], 3.0) > 1.0


def _flat_valley(x: np.ndarray):
    """A residual floor of 1 and a term that vanishes only at x1 -> infinity: the cost 0.5
    (1 + (x0 - 1)^2 + 0.01 e^(-2 x1)) falls forever by ever smaller amounts."""
    r = np.array([x[0] - 1.0, 1.0, 0.1 * math.exp(-x[1])])
    return r, None


def _flat_jacobian(x: np.ndarray, _state) -> np.ndarray:
    return np.array([[1.0, 0.0], [0.0, 0.0], [0.0, -0.1 * math.exp(-x[1])]])


# only the settled cost can end it (a short window: the cost reaches its round-off floor
# 0.5 in some 16 steps, before a window of 10 would have filled)
CREEP = LMOptions(
    max_iterations=200, step_tol=0.0, cost_rtol=0.0, predicted_rtol=0.0, settle_window=3
)


def test_a_settled_cost_ends_the_fit_and_an_unsettled_one_does_not():
    settled = levenberg_marquardt(_flat_valley, _flat_jacobian, np.zeros(2), CREEP)
    assert settled.converged and settled.message.startswith("cost settled: the last 3 steps")
    assert settled.iterations < CREEP.max_iterations
    # the cost's infimum is 0.5: what is left is below settle_rtol of the cost
    assert 0 < settled.cost - 0.5 <= CREEP.settle_rtol * settled.cost
    never = LMOptions(
        **{**CREEP.__dict__, "settle_window": 0, "max_iterations": settled.iterations}
    )
    crept = levenberg_marquardt(_flat_valley, _flat_jacobian, np.zeros(2), never)
    assert not crept.converged and crept.message == "iteration limit"
    # stopped by the limit exactly where the cost has settled: converged, and said so
    limit = LMOptions(**{**CREEP.__dict__, "max_iterations": settled.iterations})
    at_limit = levenberg_marquardt(_flat_valley, _flat_jacobian, np.zeros(2), limit)
    assert at_limit.converged
    assert at_limit.message.startswith("stopped at the iteration limit with its cost settled")
    assert at_limit.cost == settled.cost
    # one iteration short the last window has not settled yet
    short = LMOptions(**{**CREEP.__dict__, "max_iterations": settled.iterations - 1})
    assert not levenberg_marquardt(_flat_valley, _flat_jacobian, np.zeros(2), short).converged


def test_plain_with_implausible_estimates_gives_way_to_the_mildest_plausible_cut():
    """Where plain least squares is kept by cross-validation but puts an estimate beyond a
    plausible size along a direction the data barely see (the UR5 with encoder eccentricity:
    two parallel links' offsets at -+2.77 m), the mildest cut whose estimates are plausible is
    taken instead, and the reason says so; a plausible plain fit is left alone."""
    jac, residual, plain, ranges, pose = _problem(seed=2, n_poses=20, weak_truth=1.5)
    kept = choose_subspace(jac, residual, plain, ranges, pose)
    assert kept.cut is None  # plain by cross-validation (the test above)
    limit = 0.5 * float(np.max(np.abs(plain)))  # plain's largest estimate is beyond it

    def implausible(values, allow_std=True):
        big = np.flatnonzero(np.abs(values) > limit)
        return tuple(f"p{j} = {values[j]:+.3g}" for j in big)

    assert implausible(plain)
    choice = choose_subspace(jac, residual, plain, ranges, pose, implausible=implausible)
    assert choice.cut is not None and "beyond a plausible size" in choice.reason
    # its linearised estimate (from the start, in the kept directions) is plausible, and no
    # milder cut's is
    start = residual - jac @ plain
    for cut in (10.0, 3.0, 1.0):
        s = np.linalg.svd(jac, compute_uv=False)
        sigma = math.sqrt(float(residual @ residual) / (jac.shape[0] - jac.shape[1]))
        v = np.linalg.svd(jac, full_matrices=False)[2][s * cut >= sigma].T
        est = v @ np.linalg.lstsq(jac @ v, -start, rcond=None)[0]
        if cut > choice.cut:
            assert implausible(est) or v.shape[1] == jac.shape[1]
        elif cut == choice.cut:
            assert not implausible(est)
    assert (
        choose_subspace(jac, residual, plain, ranges, pose, implausible=lambda v, a=True: ()).cut
        is None
    )
