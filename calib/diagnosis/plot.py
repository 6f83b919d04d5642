"""The data of a diagnosis's figure: each pose's residual against the variable that explains it.

For a named effect, the variable its first effect acts through (an actuator's command, the
command modulo the pitch found, the gravity load, the approach direction, the tool rotation,
time), with the residual before and after the correction; for "unexplained: correlated with
<group>", the pose variable of that group that varies most. calib.diagnosis.figure draws it.
Every variable is in the units of files: lengths in mm, angles in deg (a command in mm for a
prismatic actuator, in deg for a revolute one), each named with its quantity and unit.
"""

from __future__ import annotations

import numpy as np

from calib.diagnosis.candidate import NO_SHAPE, Candidate
from calib.diagnosis.context import Context
from calib.diagnosis.fit import Evaluation
from calib.diagnosis.problem import Problem
from calib.diagnosis.unexplained import features


def _load(ctx: Context, a: int, shape: float) -> np.ndarray:
    """Actuator ``a``'s gravity load at the payload found (payload only: 1 kg)."""
    g = ctx.gravity
    assert g is not None
    if g.payload_only:
        return g.unit_payload[:, a]
    return g.own[:, a] + (shape if np.isfinite(shape) else 0.0) * g.unit_payload[:, a]


def plot_data(
    ctx: Context,
    r: np.ndarray,
    keep: np.ndarray,
    chosen: list[Candidate],
    ev: Evaluation,
    prob: Problem,
) -> dict:
    """The per-pose residual before and after against the variable the first effect uses."""
    c = chosen[0]
    var, label = ctx.time, f"time ({ctx.time_unit})"
    xs = [cc.design(ctx, s) for cc, s in zip(chosen, ev.shapes, strict=True)]
    after = r - prob.geo @ ev.fit.beta - np.concatenate(xs, axis=2) @ ev.fit.theta
    partial = None
    if c.offsets is not None:
        k0 = ev.sizes[0]
        theta = ev.fit.theta[:k0]
        off = np.einsum("nak,k->na", c.offsets(ctx, ev.shapes[0]), theta)
        a = int(np.argmax(np.sqrt(np.mean(off**2, axis=0))))
        name = ctx.actuator_names[a]
        partial = _partial(ctx, after, keep, off, a)
        factor, unit = _display(bool(ctx.is_slide[a]))
        if c.explains in ("command", "joint angle"):
            var, label = ctx.commands[:, a] * factor, f"{name} command ({unit})"
        elif c.explains == "command modulo pitch":
            pitch = float(ev.shapes[0])
            var, label = (
                np.mod(ctx.commands[:, a], pitch) * factor,
                f"{name} command modulo pitch ({unit}; pitch found {pitch * factor:.4g} {unit})",
            )
        elif c.explains == "gravity load":
            unit = "N" if ctx.is_slide[a] else "N m"
            per = " per kg of payload" if ctx.gravity.payload_only else ""
            var, label = _load(ctx, a, ev.shapes[0]), f"{name} gravity load ({unit}{per})"
        elif c.explains == "approach direction":
            var, label = -c.offsets(ctx, NO_SHAPE)[:, a, a], f"{name} approach direction"
    elif c.explains == "tool orientation":
        turn = features(ctx)["tool orientation"]
        label, var = pose_variable(ctx, "tool orientation", int(np.argmax(np.ptp(turn, axis=0))))
    elif c.explains == "distance from the tracker" and ctx.head is not None:
        var = np.linalg.norm(ctx.targets.mean(axis=1) - ctx.head, axis=1) * 1e3
        label = "distance of the tool from the tracker (mm)"
    out = plot_dict(label, var, r, after, keep)
    if partial is not None:
        out["partial"] = partial
    return out


def _partial(ctx: Context, after: np.ndarray, keep: np.ndarray, off: np.ndarray, a: int):
    """Actuator ``a``'s offset seen in each pose's readings (a partial residual): its fitted
    offset plus the least-squares offset of the residual left after all effects along its
    sensitivity J[:, a]; beside it the fitted offset. Display units: mm or deg."""
    j = ctx.j_act[:, :, a] * keep
    norm2 = np.sum(j**2, axis=1)
    seen = norm2 > 1e-12 * max(float(norm2.max()), 1e-300)
    est = np.full(len(j), np.nan)
    est[seen] = off[seen, a] + np.sum(j * after, axis=1)[seen] / norm2[seen]
    factor, unit = _display(bool(ctx.is_slide[a]))
    return {
        "label": f"{ctx.actuator_names[a]} offset ({unit})",
        "seen": (est * factor).tolist(),
        "fitted": (off[:, a] * factor).tolist(),
    }


def plot_unexplained(ctx: Context, r: np.ndarray, keep: np.ndarray, group: str, x) -> dict:
    i = int(np.argmax(np.ptp(x, axis=0) / np.maximum(np.abs(x).max(axis=0), 1e-300)))
    label, var = pose_variable(ctx, group, i, x[:, i])
    return plot_dict(label, var, r, None, keep)


def _display(slide: bool) -> tuple[float, str]:
    """SI to the units of files: m to mm for a slide, rad to deg for a revolute joint."""
    return (1e3, "mm") if slide else (float(np.degrees(1.0)), "deg")


def pose_variable(
    ctx: Context, group: str, i: int, si: np.ndarray | None = None
) -> tuple[str, np.ndarray]:
    """Column ``i`` of the pose variables ``group`` (calib.diagnosis.unexplained.features),
    named with its quantity and unit, in mm or deg (``si``: the column, if already taken)."""
    x = features(ctx)[group][:, i] if si is None else np.asarray(si, dtype=float)
    if group == "tool position":
        return f"tool {'xyz'[i]} (mm)", x * 1e3
    if group == "tool orientation":
        return f"tool rotation about {'xyz'[i]} (deg)", np.degrees(x)
    if group == "actuator commands":
        factor, unit = _display(bool(ctx.is_slide[i]))
        return f"{ctx.actuator_names[i]} command ({unit})", x * factor
    if group == "measurement order":
        return f"time ({ctx.time_unit})", x
    raise ValueError(f"no pose variable group {group!r}")


def plot_dict(label: str, var, before, after, keep) -> dict:
    """Per pose: the RMS over its kept rows (mm) before and after."""

    def size(e):
        cnt = np.maximum(keep.sum(axis=1), 1)
        return (np.sqrt(np.sum(np.where(keep, e, 0) ** 2, axis=1) / cnt) * 1e3).tolist()

    return {
        "variable": label,
        "x": np.asarray(var, float).tolist(),
        "before_mm": size(before),
        "after_mm": None if after is None else size(after),
    }
