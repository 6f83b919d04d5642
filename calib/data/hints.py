"""Likely causes of a fit that does not match the data: units, column order, target labels.

Each check compares the data as given with the same data under one simple mistake undone
(readings in other units, two actuator columns exchanged, target labels permuted), with the
*nominal* model, whose own error is millimetres at most. A mistake is named only when undoing
it lowers the 3D RMS residual by a clear factor (``CLEAR_FACTOR``): a hint, never a fix.
"""

from __future__ import annotations

import itertools

import numpy as np

from calib.fit.model import CalibrationModel
from calib.fit.position_error import error_norms
from calib.fit.registration import RegistrationError, initial_registration
from twin.exceptions import TwinError

CLEAR_FACTOR = 3.0
# scale of the readings against the model's, and the mistake it points to
UNIT_SCALES = {
    1e-3: "the readings look like metres while the dataset declares millimetres",
    1e3: "the readings look like micrometres while the dataset declares millimetres",
    1e-1: "the readings look like centimetres while the dataset declares millimetres",
    1 / 25.4: "the readings look like inches while the dataset declares millimetres",
}
UNIT_RTOL = 0.05


def _rms(measured: np.ndarray, predicted: np.ndarray, frame: str = "base") -> float:
    """3D RMS of measured against predicted; tracker-frame readings are first carried into
    the base frame by their closed-form rigid fit to the predictions."""
    if frame == "tracker":
        try:
            measured = initial_registration(measured, predicted).to_base(measured)
        except RegistrationError:
            return float("inf")
    return float(np.sqrt(np.mean(error_norms(measured, predicted) ** 2)))


def _spread(points: np.ndarray) -> float:
    p = points.reshape(-1, 3)
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))


def unit_hint(measured: np.ndarray, predicted: np.ndarray) -> str | None:
    """Readings whose spread is a unit factor off the model's (rigid-motion invariant)."""
    model_spread = _spread(predicted)
    if model_spread <= 0:
        return None
    ratio = _spread(measured) / model_spread
    for scale, text in UNIT_SCALES.items():
        if abs(ratio / scale - 1.0) < UNIT_RTOL:
            return f"{text} (their spread is {ratio:.4g} times the model's)"
    return None


def target_label_hint(
    measured: np.ndarray,
    predicted: np.ndarray,
    target_names: tuple[str, ...],
    frame: str = "base",
) -> str | None:
    """A permutation of the target labels that makes the residual clearly smaller."""
    t = measured.shape[1]
    if t < 2 or t > 5:
        return None
    base = _rms(measured, predicted, frame)
    best, best_perm = base, None
    for perm in itertools.permutations(range(t)):
        if perm == tuple(range(t)):
            continue
        r = _rms(measured[:, perm, :], predicted, frame)
        if r < best:
            best, best_perm = r, perm
    if best_perm is None or best * CLEAR_FACTOR > base:
        return None
    pairs = ", ".join(
        f"'{target_names[j]}' as '{target_names[i]}'" for i, j in enumerate(best_perm) if i != j
    )
    return (
        f"the target labels look permuted: reading {pairs} lowers the nominal residual from "
        f"{base * 1e3:.3f} to {best * 1e3:.3f} mm RMS"
    )


def actuator_order_hint(
    model: CalibrationModel,
    commands: np.ndarray,
    measured: np.ndarray,
    actuator_names: tuple[str, ...],
    frame: str = "base",
    nominal: np.ndarray | None = None,
) -> str | None:
    """Two actuator columns whose exchange makes the nominal residual clearly smaller;
    ``nominal``: the nominal targets at ``commands`` (None: they did not solve)."""
    x0 = np.zeros(model.n_parameters)
    base = np.inf if nominal is None else _rms(measured, nominal, frame)
    best, best_pair = base, None
    for i, j in itertools.combinations(range(commands.shape[1]), 2):
        swapped = commands.copy()
        swapped[:, [i, j]] = swapped[:, [j, i]]
        try:
            r = _rms(measured, model.predict(x0, swapped).targets, frame)
        except TwinError:
            continue
        if r < best:
            best, best_pair = r, (i, j)
    if best_pair is None or not (best * CLEAR_FACTOR < base):
        return None
    a, b = (actuator_names[k] for k in best_pair)
    was = "does not solve" if not np.isfinite(base) else f"is {base * 1e3:.3f} mm RMS"
    return (
        f"actuator columns '{a}' and '{b}' look exchanged: the nominal residual {was} as given "
        f"and {best * 1e3:.3f} mm RMS with them swapped"
    )


def likely_causes(
    model: CalibrationModel,
    commands: np.ndarray,
    measured: np.ndarray,
    target_names: tuple[str, ...],
    frame: str = "base",
) -> list[str]:
    """Every hint that the data shows, most specific first (nominal model, cold starts)."""
    state = model.state
    model = CalibrationModel(model.nominal, model.params)  # no warm start from a failed fit
    model.bind_state(state)  # of these readings, for the offset kinds
    x0 = np.zeros(model.n_parameters)
    hints: list[str] = []
    try:
        nominal = model.predict(x0, commands).targets
    except TwinError:
        nominal = None
    if nominal is not None:
        for hint in (
            unit_hint(measured, nominal),
            target_label_hint(measured, nominal, target_names, frame),
        ):
            if hint:
                hints.append(hint)
    hint = actuator_order_hint(
        model, commands, measured, model.nominal.actuator_names, frame, nominal
    )
    if hint:
        hints.append(hint)
    return hints
