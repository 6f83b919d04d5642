"""The residual correction as one object: the kernel ridge fit, its guard, its file block.

``ResidualCorrection.predict`` gives, for poses' features (commands, tool position), the
correction of every reading (N, T*3, metres), its predictive standard deviation per pose
and whether the pose is inside the calibrated region: a pose whose standardised feature
distance to the nearest pose that carries the correction exceeds ``guard_radius`` (the
farthest the cross-validation showed the correction still lowering the held-out error)
gets none. In files (``residual_correction`` of a diagnosis or a result, the sidecar of an
exported model) the features' scaling is in deg and mm, the weights in mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calib.correction.kernel_ridge import CrossValidation, KernelRidge, nearest
from calib.exceptions import CalibError

FORMAT = "kernel-ridge-rbf/1"
# the guard judges the farthest held-out poses in groups of at least this many (or 10 %)
GUARD_GROUP = 5


class CorrectionFileError(CalibError):
    """A residual_correction block that is malformed or made for another machine."""


def pose_features(commands: np.ndarray, positions: np.ndarray | None) -> np.ndarray:
    """Features (N, A [+3]): the commands, and the tool position (mean of the targets)
    where given (an arm's commands alone do not say where the tool is as directly)."""
    c = np.asarray(commands, dtype=float)
    if positions is None:
        return c
    return np.hstack([c, np.asarray(positions, dtype=float).reshape(len(c), 3)])


def feature_names(actuators: tuple[str, ...], slide: tuple[bool, ...], with_position: bool):
    """Names and file units of the features."""
    names = [f"cmd:{a}" for a in actuators]
    units = ["mm" if s else "deg" for s in slide]
    if with_position:
        names += ["tool x", "tool y", "tool z"]
        units += ["mm"] * 3
    return tuple(names), tuple(units)


def guard_radius(cv: CrossValidation, group: int = GUARD_GROUP) -> float:
    """The farthest standardised distance the cross-validation supports: the held-out poses
    sorted by distance to their fold's training poses, the farthest dropped one by one while
    the farthest ``group`` (at least 10 %) of those left are made worse (held-out SSE after
    >= before); the radius is the largest distance left (0 when too few are left)."""
    n = len(cv.distance)
    m = max(group, math.ceil(0.1 * n))
    order = np.argsort(-cv.distance, kind="stable")
    before = np.sum(cv.before**2, axis=1)[order]
    after = np.sum(cv.after**2, axis=1)[order]
    for start in range(0, n - m + 1):
        tail = slice(start, start + m)
        if np.sum(after[tail]) < np.sum(before[tail]):
            return float(cv.distance[order[start]])
    return 0.0


@dataclass(frozen=True)
class ResidualCorrection:
    kr: KernelRidge
    guard_radius: float
    names: tuple[str, ...]  # feature names
    units: tuple[str, ...]  # their file units, "deg" or "mm"
    n_targets: int
    summary: dict[str, Any] = field(default_factory=dict)  # the numbers that offered it

    @property
    def with_position(self) -> bool:
        return "tool x" in self.names

    def predict(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """At features ``x`` (N, d), SI: ``mean`` (N, T*3) m (zero outside), ``std`` (N,) m
        per coordinate, ``inside`` (N,) bool, ``distance`` (N,) standardised."""
        x = np.asarray(x, dtype=float)
        mean, std = self.kr.predict(x)
        distance = nearest(self.kr.standardise(x), self.kr.z_train)
        inside = distance <= self.guard_radius
        return {
            "mean": np.where(inside[:, None], mean, 0.0),
            "std": std,
            "inside": inside,
            "distance": distance,
        }

    def predict_held_out(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """As :meth:`predict`, but a pose that is one of those carrying the correction gets
        the correction fitted without it (leave-one-out): what holding the correction in a
        refit of the same poses may use, or its in-sample fit (which interpolates them)
        would leave the refit nothing but noise to see."""
        out = self.predict(x)
        z = self.kr.standardise(x)
        loo = None
        for i in np.flatnonzero(out["distance"] <= 1e-9):
            if loo is None:
                loo = self.kr.loo_mean()
            j = int(np.argmin(np.sum((self.kr.z_train - z[i]) ** 2, axis=1)))
            out["mean"][i] = loo[j] if out["inside"][i] else 0.0
        return out

    def to_dict(self, model_name: str) -> dict[str, Any]:
        u = _factors(self.units)
        kr = self.kr
        return {
            "format": FORMAT,
            "model": model_name,
            "features": list(self.names),
            "feature_units": list(self.units),
            "feature_mean": (kr.mean * u).tolist(),
            "feature_scale": (kr.scale * u).tolist(),
            "training_features_standardised": kr.z_train.tolist(),
            "weights_mm": (kr.weights * 1e3).tolist(),
            "length_scale": kr.length_scale,
            "noise_to_signal_ratio": kr.ratio,
            "signal_std_mm": math.sqrt(kr.signal_var) * 1e3,
            "guard_radius": self.guard_radius,
            "n_targets": self.n_targets,
            "summary": self.summary,
        }

    @classmethod
    def from_dict(cls, d: Any, where: str, model_name: str | None = None) -> ResidualCorrection:
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise CorrectionFileError(f"{where}: no residual_correction of format {FORMAT}")
        if model_name is not None and d.get("model") != model_name:
            raise CorrectionFileError(
                f"{where}: the residual correction is for model '{d.get('model')}', not "
                f"'{model_name}'"
            )
        try:
            units = tuple(str(s) for s in d["feature_units"])
            u = _factors(units)
            z = np.array(d["training_features_standardised"], dtype=float)
            w = np.array(d["weights_mm"], dtype=float) * 1e-3
            kr = KernelRidge(
                z_train=z.reshape(len(z), len(units)),
                weights=w.reshape(len(z), -1),
                length_scale=float(d["length_scale"]),
                ratio=float(d["noise_to_signal_ratio"]),
                signal_var=(float(d["signal_std_mm"]) * 1e-3) ** 2,
                mean=np.array(d["feature_mean"], dtype=float) / u,
                scale=np.array(d["feature_scale"], dtype=float) / u,
            )
            out = cls(
                kr,
                float(d["guard_radius"]),
                tuple(str(s) for s in d["features"]),
                units,
                int(d["n_targets"]),
                dict(d.get("summary") or {}),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise CorrectionFileError(f"{where}: malformed residual_correction ({exc})") from None
        if out.kr.weights.shape[1] != 3 * out.n_targets or not np.all(np.isfinite(out.kr.weights)):
            raise CorrectionFileError(
                f"{where}: residual_correction weights do not fit its targets"
            )
        return out


def _factors(units: tuple[str, ...]) -> np.ndarray:
    """SI -> file unit factor per feature."""
    table = {"deg": 180.0 / math.pi, "mm": 1e3}
    bad = [x for x in units if x not in table]
    if bad:
        raise CorrectionFileError(f"unknown feature unit(s) {bad}: expected deg or mm")
    return np.array([table[x] for x in units])
