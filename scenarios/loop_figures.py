"""The loop's cause, one figure per named effect: each pose's residual before and after the
effect against the variable that explains it.

A named effect of the diagnosis acts through one variable: an actuator's command, the command
modulo the pitch found, the approach direction, the time of measurement. For the first named
effect the diagnosis's own figure (calib.diagnosis.figure, the report's) is that figure. For
every further one, this module draws the residual without that effect (the others applied)
and with all the named effects, against its variable, computed from the commands and the
order as the diagnosis's library defines them (calib.diagnosis.candidates' ``explains``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calib.diagnosis import default_candidates, effect_offsets
from calib.fit import CalibrationModel

Predict = Callable[[dict[str, np.ndarray]], np.ndarray]  # named effects -> targets (N, T, 3)


@dataclass(frozen=True)
class EffectPlot:
    """One named effect's figure data: the variable, and each pose's residual (mm)."""

    effect: str
    variable: str  # the axis label, with its unit
    x: np.ndarray
    without_mm: np.ndarray  # the other named effects applied, this one not
    with_mm: np.ndarray  # all named effects applied


def per_pose_rms_mm(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Each pose's residual, RMS over its coordinates (mm): the diagnosis figure's measure."""
    d = np.asarray(measured) - np.asarray(predicted)
    return np.sqrt(np.mean(d.reshape(len(d), -1) ** 2, axis=1)) * 1e3


def effect_variable(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    effect: str,
    coefficients: np.ndarray,
    time_origin: float = 0.0,
    time_unit: str = "pose",
) -> tuple[str, np.ndarray]:
    """The variable ``effect`` acts through, per pose, and its label (display units)."""
    mech = model.nominal
    lib = {
        c.name: c
        for c in default_candidates(
            mech.actuator_names, mech.actuator_is_slide, mech.masses_defaulted
        )
    }
    cand = lib.get(effect)
    order = np.asarray(order, dtype=float)
    when = (f"measurement order ({time_unit})", order)
    if cand is None or cand.offsets is None or cand.explains == "time":
        return when
    offsets = effect_offsets(
        model, values, commands, order, {effect: coefficients}, None, time_origin, time_unit
    )
    a = int(np.argmax(np.sqrt(np.mean(offsets**2, axis=0))))
    slide = bool(mech.actuator_is_slide[a])
    factor, unit = (1e3, "mm") if slide else (np.degrees(1.0), "deg")
    name = mech.actuator_names[a]
    command = np.asarray(commands, dtype=float)[:, a]
    if cand.explains == "command modulo pitch":
        pitch = float(np.asarray(coefficients)[-1])
        label = f"{name} command modulo {pitch * factor:.3g} {unit} ({unit})"
        return label, np.mod(command, pitch) * factor
    if cand.explains == "approach direction":
        ranked = np.argsort(order, kind="stable")
        step = np.zeros(len(command))
        step[ranked[1:]] = np.diff(command[ranked])
        return f"{name} approach direction (sign of its last move)", np.sign(step)
    if cand.explains in ("command", "joint angle"):
        return f"{name} command ({unit})", command * factor
    return when


def effect_plots(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    measured: np.ndarray,
    coefficients: dict[str, np.ndarray],
    predict: Predict,
    time_origin: float = 0.0,
    time_unit: str = "pose",
) -> list[EffectPlot]:
    """One :class:`EffectPlot` per named effect (``coefficients``, the diagnosis's)."""
    with_all = per_pose_rms_mm(measured, predict(coefficients))
    plots = []
    for effect, coef in coefficients.items():
        others = {k: v for k, v in coefficients.items() if k != effect}
        label, x = effect_variable(
            model, values, commands, order, effect, coef, time_origin, time_unit
        )
        without = per_pose_rms_mm(measured, predict(others))
        plots.append(EffectPlot(effect, label, np.asarray(x, float), without, with_all))
    return plots


def effect_png(plot: EffectPlot, noise_mm: float, others: list[str]) -> bytes:
    """The figure of one named effect: residual per pose without and with it."""
    from scenarios.figures import plt, png_bytes

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    besides = f" ({', '.join(others)} applied)" if others else ""
    ax.plot(plot.x, plot.without_mm, "o", ms=4, label=f"without {plot.effect}{besides}")
    ax.plot(plot.x, plot.with_mm, "s", ms=4, label="with every named effect")
    ax.axhline(noise_mm, color="k", lw=0.8, ls="--", label="noise per coordinate")
    ax.set_xlabel(plot.variable, fontsize=11)
    ax.set_ylabel("residual per pose, RMS\nper coordinate (mm)", fontsize=11)
    ax.tick_params(labelsize=10)
    ax.set_title(f"{plot.effect}: the residual against {plot.variable}", fontsize=11)
    ax.legend(fontsize=10)
    fig.tight_layout()
    return png_bytes(fig)


def heldout_png(ratio: dict[str, float], chosen: str) -> bytes:
    """Each candidate's held-out RMS over the noise, named on its bar (log axis: one far-off
    candidate does not flatten the others); the named effects' bars stand out."""
    from scenarios.figures import plt, png_bytes

    names = list(ratio)
    values = np.array([ratio[n] for n in names], dtype=float)
    named = set(chosen.split("+"))
    fig, ax = plt.subplots(figsize=(6.4, 1.2 + 0.34 * len(names)))
    colours = ["#e45756" if n in named else "#4c78a8" for n in names]
    y = np.arange(len(names))[::-1]
    ax.barh(y, np.where(np.isfinite(values), values, np.nan), color=colours)
    ax.set_yticks(y, names, fontsize=10)
    ax.set_xscale("log")
    ax.axvline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel("held-out RMS / noise per coordinate (log; 1 = the noise)", fontsize=10)
    ax.tick_params(axis="x", labelsize=10)
    ax.set_title(f"candidates held out; named: {chosen}", fontsize=11)
    fig.tight_layout()
    return png_bytes(fig)
