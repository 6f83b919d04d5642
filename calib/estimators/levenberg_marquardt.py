"""Levenberg-Marquardt for nonlinear least squares with a caller-supplied Jacobian.

Minimises ``0.5 |r(x)|^2``. Steps are solved on the column-scaled Jacobian (Marquardt's
scaling: the damping acts on each parameter in proportion to its own curvature), the damping
follows Nielsen's gain-ratio rule, and a trial point whose evaluation fails (for a closed
chain: a closure that does not solve) counts as a rejected step.

Once a step has shown curvature (a gain ratio below ``GAIN_CURVED``, or a rejected trial),
every further step gets geodesic acceleration (Transtrum and Sethna, "Improvements to the
Levenberg-Marquardt algorithm for nonlinear least-squares minimization", 2012; as in GSL's
``lmaccel``): the second derivative of the residual along the step, by one extra evaluation
a fraction ``geodesic_h`` of the step away, bends the step along a curved valley. Such a
valley is what a nearly redundant pair leaves (a hexapod's base tilt against a tracker
registration's): plain steps crawled along it for 88 iterations, accelerated ones took 21.
A well-conditioned fit (gain ratios near 1) never pays for the extra evaluation.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calib.exceptions import ConvergenceError


@dataclass(frozen=True)
class LMOptions:
    max_iterations: int = 50
    step_tol: float = 1e-12  # stop when max |dx| (SI) falls below this
    cost_rtol: float = 1e-14  # or the relative cost decrease below this
    # relative to the column-scaled curvature: calibration starts near the answer (nominal
    # geometry within millimetres), so start close to Gauss-Newton; a rejected step raises
    # the damping geometrically (Nielsen). From 1e-3, 8 of 13 iterations of a hexapod fit
    # did nothing but lower the damping; from 1e-9, a few-pose noise-free fit of a random
    # hexapod truth ran to another exact root (tests/test_scenario_hexapod.py).
    initial_damping: float = 1e-6
    # stop when the undamped (Gauss-Newton) step predicts a relative cost decrease below this:
    # a closed-chain residual is solved to ~1e-15 m per coordinate, so its cost is known to
    # ~1e-10 relative at the noise floor, and smaller predicted decreases were only ever
    # rejected trial steps (8 of 13 evaluations of a hexapod fit); 0 disables the test
    predicted_rtol: float = 1e-10
    # geodesic acceleration once a step has shown curvature (module docstring); the
    # accelerated step is taken only if 2 |a| <= geodesic_ratio |v| (Transtrum's alpha), else
    # the plain one (near an exact fit the finite difference measures round-off)
    geodesic: bool = True
    geodesic_h: float = 0.1
    geodesic_ratio: float = 0.75
    # a settled cost: over the last ``settle_window`` accepted steps the cost fell by at most
    # ``settle_rtol`` of itself in all, and the undamped step predicts no more than that
    # either. A fit creeping along a flat valley (weak directions) meets neither the step
    # nor the per-step cost test for hundreds of iterations while its cost is already known
    # to far below the noise: 1e-9 of the cost is a chi-square change below 1e-9 x the
    # degrees of freedom (a millionth of a standard error at 1e3 readings), nothing the
    # data can tell. A quadratically converging fit drops its predicted decrease from 1e-9
    # below ``predicted_rtol`` in one or two steps, so it never waits for the window.
    # 0 disables the test
    settle_window: int = 10
    settle_rtol: float = 1e-9


# a gain ratio below this (or a rejected trial): the quadratic model missed, the path is
# curved; from then on every step of the fit is accelerated
GAIN_CURVED = 0.75


@dataclass(frozen=True)
class LMResult:
    x: np.ndarray
    residual: np.ndarray
    jacobian: np.ndarray  # of the residual at x
    cost: float
    iterations: int
    converged: bool
    history: list[float] = field(default_factory=list)  # cost after each accepted step
    message: str = ""


ResidualFn = Callable[[np.ndarray], tuple[np.ndarray, Any]]
JacobianFn = Callable[[np.ndarray, Any], np.ndarray]


def levenberg_marquardt(
    residual: ResidualFn,
    jacobian: JacobianFn,
    x0: np.ndarray,
    options: LMOptions | None = None,
    recoverable: tuple[type[BaseException], ...] = (),
    start: tuple[np.ndarray, np.ndarray] | None = None,
) -> LMResult:
    """Minimise ``|r(x)|^2``; ``residual(x)`` returns (r, state), ``jacobian(x, state)`` dr/dx.

    ``recoverable`` lists exceptions that make a trial step fail instead of the whole solve.
    ``start``: the residual and Jacobian at ``x0`` when the caller has them already (they
    must be what ``residual`` and ``jacobian`` return there), saving their evaluation.
    """
    opt = options or LMOptions()
    x = np.array(x0, dtype=float)
    if start is None:
        r, state = residual(x)
        jac = jacobian(x, state)
    else:
        r, jac = start
    cost = 0.5 * float(r @ r)
    history = [cost]
    damping, nu = opt.initial_damping, 2.0
    curved = False
    for it in range(1, opt.max_iterations + 1):
        scale = np.linalg.norm(jac, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        js = jac / scale
        a = js.T @ js
        g = js.T @ r
        gn_decrease = _gauss_newton_decrease(a, g)
        if gn_decrease <= opt.predicted_rtol * cost:
            # not even the undamped step could lower the cost by more than the evaluation's
            # round-off: converged (trial steps would only be rejected, raising the damping)
            return LMResult(x, r, jac, cost, it - 1, True, history, "converged")
        settled = _settled(history, gn_decrease, opt)
        if settled:
            return LMResult(x, r, jac, cost, it - 1, True, history, f"cost settled: {settled}")
        accepted = False
        while not accepted:
            damped = a + damping * np.eye(len(x))
            velocity_s = _solve(damped, -g)
            # the quadratic model's decrease for the velocity: the acceleration corrects the
            # path for a curvature that model does not see (Transtrum and Sethna)
            predicted = -(g @ velocity_s) - 0.5 * velocity_s @ a @ velocity_s
            step_s = velocity_s
            if opt.geodesic and curved:
                step_s = _accelerated(
                    residual, x, r, jac, js, scale, damped, velocity_s, opt, recoverable
                )
            step = step_s / scale
            try:
                r_new, state_new = residual(x + step)
                cost_new = 0.5 * float(r_new @ r_new)
            except recoverable:
                cost_new, r_new, state_new = np.inf, None, None
            gain = (cost - cost_new) / predicted if predicted > 0 else -1.0
            curved = curved or not (np.isfinite(cost_new) and gain >= GAIN_CURVED)
            if np.isfinite(cost_new) and gain > 0:
                accepted = True
                x = x + step
                r, state = r_new, state_new
                decrease = cost - cost_new
                cost = cost_new
                history.append(cost)
                damping *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
                nu = 2.0
                jac = jacobian(x, state)
                small_step = np.max(np.abs(step)) < opt.step_tol
                small_decrease = decrease <= opt.cost_rtol * max(cost, 1e-300)
                if small_step or small_decrease or cost == 0.0:
                    return LMResult(x, r, jac, cost, it, True, history, "converged")
            else:
                if np.max(np.abs(step)) < opt.step_tol:
                    return LMResult(x, r, jac, cost, it, True, history, "no further decrease")
                damping *= nu
                nu *= 2.0
                if damping > 1e16:
                    raise ConvergenceError(
                        f"Levenberg-Marquardt stalled at iteration {it}: no step decreases "
                        f"the cost {cost:.4g}"
                    )
    scale = np.linalg.norm(jac, axis=0)
    js = jac / np.where(scale > 0, scale, 1.0)
    settled = _settled(history, _gauss_newton_decrease(js.T @ js, js.T @ r), opt)
    if settled:
        return LMResult(
            x,
            r,
            jac,
            cost,
            opt.max_iterations,
            True,
            history,
            f"stopped at the iteration limit with its cost settled: {settled}",
        )
    return LMResult(x, r, jac, cost, opt.max_iterations, False, history, "iteration limit")


def _settled(history: list[float], gn_decrease: float, opt: LMOptions) -> str:
    """Why the cost has settled (``LMOptions.settle_window``), in words; "" if it has not:
    the last window's accepted steps lowered it by at most ``settle_rtol`` of itself and the
    undamped step predicts no more."""
    w = opt.settle_window
    if w <= 0 or len(history) <= w or not history[-1] > 0:
        return ""
    cost = history[-1]
    fell = history[-1 - w] - cost
    limit = opt.settle_rtol * cost
    if not (fell <= limit and gn_decrease <= limit):
        return ""
    return (
        f"the last {w} steps lowered the cost by {fell / cost:.2g} of itself and the "
        f"Gauss-Newton step predicts {gn_decrease / cost:.2g} more"
    )


def _solve(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.solve(matrix, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(matrix, rhs, rcond=None)[0]


def _accelerated(
    residual: ResidualFn,
    x: np.ndarray,
    r: np.ndarray,
    jac: np.ndarray,
    js: np.ndarray,
    scale: np.ndarray,
    damped: np.ndarray,
    step_s: np.ndarray,
    opt: LMOptions,
    recoverable: tuple[type[BaseException], ...],
) -> np.ndarray:
    """The scaled step ``v`` with geodesic acceleration, ``v + a / 2``; ``v`` itself when
    the extra evaluation fails or ``2 |a| > ratio |v|`` (Transtrum's test)."""
    h = opt.geodesic_h
    velocity = step_s / scale
    try:
        r_h, _ = residual(x + h * velocity)
    except recoverable:
        return step_s
    second = (2.0 / h) * ((r_h - r) / h - jac @ velocity)  # r'' along the step
    acc_s = _solve(damped, -(js.T @ second))
    if not 2.0 * np.linalg.norm(acc_s) <= opt.geodesic_ratio * np.linalg.norm(step_s):
        return step_s
    return step_s + 0.5 * acc_s


def _gauss_newton_decrease(a: np.ndarray, g: np.ndarray) -> float:
    """The cost decrease the undamped (Gauss-Newton) step predicts, 0.5 g^T a^-1 g; infinite
    when ``a`` is singular (no conclusion drawn)."""
    try:
        step = np.linalg.solve(a, g)
    except np.linalg.LinAlgError:
        return np.inf
    value = 0.5 * float(g @ step)
    return value if np.isfinite(value) else np.inf


@dataclass(frozen=True)
class ReweightedResult:
    fit: LMResult  # of the last weighted solve (its residual and Jacobian are weighted)
    residual: np.ndarray  # unweighted residual at fit.x
    weights: np.ndarray  # per group of ``group`` rows, the ones of the last solve
    rounds: int
    iterations: int  # Levenberg-Marquardt iterations over all rounds


WeightFn = Callable[[np.ndarray], np.ndarray]


def reweighted_levenberg_marquardt(
    residual: ResidualFn,
    jacobian: JacobianFn,
    x0: np.ndarray,
    weights: WeightFn,
    group: int = 1,
    options: LMOptions | None = None,
    recoverable: tuple[type[BaseException], ...] = (),
    max_rounds: int = 20,
    weight_tol: float = 1e-3,
) -> ReweightedResult:
    """Iteratively reweighted least squares (an M-estimator) solved by Levenberg-Marquardt.

    ``weights(r)`` maps an unweighted residual to one positive weight per group of ``group``
    consecutive rows (a 3D reading: its rows share a weight, judged by their joint norm);
    each round minimises ``sum_g w_g |r_g(x)|^2`` with the weights of the previous round's
    residual, until no weight changes by more than ``weight_tol`` (or ``max_rounds``).
    """
    x = np.array(x0, dtype=float)
    r0, _ = residual(x)
    w = np.asarray(weights(r0), dtype=float)
    total = 0
    for rounds in range(1, max_rounds + 1):
        root = np.repeat(np.sqrt(w), group)

        def weighted(xx: np.ndarray, root=root) -> tuple[np.ndarray, Any]:
            r, state = residual(xx)
            return root * r, state

        def weighted_jacobian(xx: np.ndarray, state: Any, root=root) -> np.ndarray:
            return root[:, None] * jacobian(xx, state)

        fit = levenberg_marquardt(weighted, weighted_jacobian, x, options, recoverable)
        total += fit.iterations
        x = fit.x
        r = fit.residual / root
        w_new = np.asarray(weights(r), dtype=float)
        change = float(np.max(np.abs(w_new - w))) if w.size else 0.0
        if change <= weight_tol:
            return ReweightedResult(fit, r, w, rounds, total)
        w = w_new
    return ReweightedResult(fit, r, w, max_rounds, total)
