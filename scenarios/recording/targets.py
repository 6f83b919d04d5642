"""What a recording shows of a pose's targets: each target's nominal point in its own colour,
the error as an arrow magnified to be seen (the measured point at its tip), each error's size
as a label set off from the targets with a leader line (the magnification is in the view's
name: no text in the scene but the errors' sizes).

Pure functions of the positions (metres), shared by the pose-by-pose and the column-wise
logging of ``scenarios.recording.recorder``.
"""

from __future__ import annotations

import math

import numpy as np

TARGET_RADIUS = 0.003  # metres, at least
ARROW_SHARE = 0.8  # the largest arrow as a share of the targets' spread
FIELD_SHARE = 0.3  # the largest arrow of a field of nodes as a share of the field's extent
LABEL_OFFSET = 0.15  # a label's distance from its target, as a share of the spread
# each target's nominal point (1, 2, 3 ...): blue, green, purple, brown, teal; the measured
# point orange and the error arrow red, so that none is taken for another
TARGET_COLOURS = [[40, 110, 220], [40, 160, 80], [150, 80, 200], [140, 90, 40], [20, 160, 170]]
MEASURED_COLOUR, ERROR_COLOUR, LEADER_COLOUR = [255, 140, 0], [220, 30, 30], [120, 120, 120]
# the machine views look along -(1, -1.3, 0.8) (blueprints.Bounds.eye): to their right
SCREEN_RIGHT = np.array([1.3, 1.0, 0.0]) / np.hypot(1.3, 1.0)


def spread(nominal: np.ndarray, least: float = 0.05) -> float:
    """The largest side of the box around the targets (metres), at least ``least``."""
    p = np.asarray(nominal, dtype=float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    if not len(p):
        return least
    return max(float(np.max(np.ptp(p, axis=0))), least)


def arrow_scale(nominal: np.ndarray, measured: np.ndarray, length: float | None = None) -> float:
    """A 1-2-5 magnification that draws the largest error as at most ``length`` metres
    (default 80 % of the targets' spread over all poses): errors of micrometres on a machine
    of a metre stay visible."""
    err = np.linalg.norm(np.asarray(measured) - np.asarray(nominal), axis=-1)
    largest = float(np.max(err[np.isfinite(err)], initial=0.0))
    if largest <= 0.0:
        return 1.0
    raw = (ARROW_SHARE * spread(nominal) if length is None else float(length)) / largest
    decade = 10.0 ** math.floor(math.log10(raw))
    return max(m * decade for m in (1.0, 2.0, 5.0) if m * decade <= raw * (1 + 1e-12))


def field_scale(nominal: np.ndarray, measured: np.ndarray) -> float:
    """:func:`arrow_scale` for a field of nodes (N, 3) shown at once, in a view framed on the
    field: the largest arrow at most 30 % of the field's extent (between 12 % and 30 % after the
    1-2-5 rounding), whatever the errors' size, so that every stage's view shows
    arrows of the same length on the screen."""
    p = np.asarray(nominal, dtype=float).reshape(-1, 3)
    return arrow_scale(p, measured, FIELD_SHARE * spread(p))


def target_colours(n_poses: int, n_targets: int) -> np.ndarray:
    """Each target's colour (flat over poses and targets, (P * T, 3) uint8)."""
    palette = np.array(TARGET_COLOURS, dtype=np.uint8)
    return np.tile(palette[np.arange(n_targets) % len(palette)], (n_poses, 1))


def label_positions(nominal: np.ndarray, span: float) -> np.ndarray:
    """Where each target's label goes (P, T, 3): away from the pose's other targets and up,
    each target a little higher than the one before, so that labels do not lie on each other."""
    p = np.asarray(nominal, dtype=float)
    if p.ndim == 2:
        p = p[None]
    out = p - p.mean(axis=1, keepdims=True)
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    out = np.where(norm > 1e-9, out / np.maximum(norm, 1e-300), 0.0)
    if p.shape[1] == 1:  # a lone target: to its right as the machine views look, not on it
        out[..., :] = 2.0 * SCREEN_RIGHT
    up = np.zeros_like(p)
    up[..., 2] = 0.5 + 0.5 * np.arange(p.shape[1])[None, :]
    return p + LABEL_OFFSET * span * (out + up)


def error_labels(nominal: np.ndarray, measured: np.ndarray) -> list[str]:
    """Each target's error in mm (flat over poses and targets)."""
    err = np.linalg.norm(np.asarray(measured) - np.asarray(nominal), axis=-1).ravel() * 1e3
    return [f"{e:.3f} mm" for e in err]


def radii(span: float) -> tuple[float, float]:
    """The radius of a target's point and of an error arrow (metres) for targets spread over
    ``span``: 1.5 % and 0.8 % of it, so that both are seen in a view framed on the machine."""
    return max(TARGET_RADIUS, 0.015 * span), max(TARGET_RADIUS / 2, 0.008 * span)
