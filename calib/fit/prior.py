"""What the poses barely determine: weakly identified parameters, and a prior that holds them.

A parameter can be identifiable in the exact sense (full rank) and still be determined only
to tens of millimetres by noisy readings. Such a parameter is *weakly identified* when its
standard error exceeds half its prior range: the size an error of its kind can physically
have (``--prior-std``, per kind: lengths in mm, angles in deg). Near-collinear groups are the
sets of parameters linked by correlations above 0.95; they explain why.

With a prior, identification adds the rows ``sigma (x_i - 0) / prior_std_i`` (sigma the
tracker noise per coordinate) to the least-squares problem: a Gaussian prior of zero mean,
the maximum a posteriori estimate (ridge regression in physical units). It keeps weakly
identified parameters physical and barely moves well-determined ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.offset_kinds import offset_range

WEAK_FRACTION = 0.5  # weakly identified: std error above this fraction of the prior range
# ... unless the value lies this many standard errors from zero (its sign and size are then
# determined to a third or better, whatever the physical range says)
DETERMINED_Z = 3.0
COLLINEAR_R = 0.95
DEFAULT_RANGE = {"length": 1.0, "angle": 0.1}  # mm, deg: assembly errors of a built machine
# an actuator's scale (ppm): a screw's lead or a gear ratio is within a few hundred ppm, a
# revolution-to-mm factor set by hand can be off by per cent; 1 % is the range's unit
GAIN_RANGE_PPM = 1e4
# a joint compliance (SI): a size-20 harmonic drive (1e4 N m/rad), a soft prismatic leg
# (1e6 N/m); per kg of payload (a model without masses) under up to 10 kg
COMPLIANCE_RANGE = {"turning": 1e-4, "sliding": 1e-6, "payload_kg": 10.0}


@dataclass(frozen=True)
class PriorSpec:
    """Prior standard deviations by kind, in file units (mm, deg); None: that kind free."""

    length_mm: float | None = None
    angle_deg: float | None = None

    @classmethod
    def parse(cls, text: str) -> PriorSpec:
        """``length=1,angle=0.1`` (mm, deg); either may be left out."""
        values: dict[str, float] = {}
        for part in filter(None, (p.strip() for p in text.split(","))):
            key, sep, raw = part.partition("=")
            key = key.strip()
            if not sep or key not in ("length", "angle"):
                raise ValueError(
                    f"prior '{part}': write kind=value with kind 'length' (mm) or 'angle' "
                    "(deg), e.g. length=1,angle=0.1"
                )
            try:
                v = float(raw)
            except ValueError:
                raise ValueError(f"prior '{part}': {raw.strip()!r} is not a number") from None
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"prior '{part}': the standard deviation must be > 0")
            if key in values:
                raise ValueError(f"prior '{text}': '{key}' is given twice; give each kind once")
            values[key] = v
        if not values:
            raise ValueError("an empty prior: give length=... and/or angle=...")
        return cls(values.get("length"), values.get("angle"))

    def std_si(self, is_angle: np.ndarray, is_gain: np.ndarray | None = None) -> np.ndarray:
        """Per-parameter prior std in SI (inf where the kind has none: gains have none)."""
        length = math.inf if self.length_mm is None else self.length_mm * 1e-3
        angle = math.inf if self.angle_deg is None else math.radians(self.angle_deg)
        std = np.where(np.asarray(is_angle, dtype=bool), angle, length)
        return std if is_gain is None else np.where(np.asarray(is_gain, bool), math.inf, std)

    def as_dict(self) -> dict:
        return {"length_mm": self.length_mm, "angle_deg": self.angle_deg}


@dataclass(frozen=True)
class Prior:
    """Prior rows for the free parameters: std (SI, inf = none) and the noise sigma (m)."""

    std: np.ndarray
    noise_sigma_m: float

    def weights(self) -> np.ndarray:
        return self.noise_sigma_m / self.std  # 0 where std is inf


def physical_ranges(params: Any, spec: PriorSpec | None = None) -> np.ndarray:
    """Each parameter's physical range in SI: the size an error of its kind can have on a
    built machine (``spec``'s, else ``DEFAULT_RANGE``; ``GAIN_RANGE_PPM`` for an actuator
    gain, ``COMPLIANCE_RANGE`` for a joint compliance): the unit in which the estimates'
    sizes are compared (calib.fit.redundancy) and the weak directions judged
    (calib.fit.regularisation). ``params``: a ParameterSet."""
    length = DEFAULT_RANGE["length"] if spec is None or spec.length_mm is None else spec.length_mm
    angle = DEFAULT_RANGE["angle"] if spec is None or spec.angle_deg is None else spec.angle_deg
    out = np.where(np.asarray(params.is_angle, dtype=bool), math.radians(angle), length * 1e-3)
    out = np.where(np.asarray(params.is_gain, dtype=bool), GAIN_RANGE_PPM * 1e-6, out)
    out = _offset_ranges(params, out)
    if not getattr(params, "has_compliance", False):
        return out
    r = COMPLIANCE_RANGE
    comp = np.where(params.turns, r["turning"], r["sliding"])
    comp = np.where(np.isnan(params.payload_kg), comp * r["payload_kg"], comp)
    return np.where(params.is_compliance, comp, out)


def _offset_ranges(params: Any, out: np.ndarray) -> np.ndarray:
    """The offset kinds' ranges (twin.offset_kinds.offset_range) in ``out``."""
    out = np.array(out, dtype=float)
    for k in np.flatnonzero(getattr(params, "is_offset", ())):
        p = params.parameters[k]
        out[k] = offset_range(p.kind, bool(params.turns[k]), p.constants_dict)
    return out


def padded_rows(weights: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Prior residual rows ``w * x`` and their Jacobian ``diag(w)`` over the priored
    parameters, padded with zero rows to a multiple of 3 (readings are groups of 3 rows)."""
    idx = np.flatnonzero(weights > 0)
    rows = -(-len(idx) // 3) * 3
    r = np.zeros(rows)
    jac = np.zeros((rows, len(x)))
    r[: len(idx)] = weights[idx] * x[idx]
    jac[np.arange(len(idx)), idx] = weights[idx]
    return r, jac


def weakly_identified(
    names: tuple[str, ...],
    std_si: np.ndarray,
    params: Any,
    ranges: PriorSpec | None = None,
    values_si: np.ndarray | None = None,
) -> list[dict]:
    """Estimated parameters whose standard error exceeds half their physical range
    (``params``: the ParameterSet, for each one's kind and display unit) and, given their
    ``values_si``, whose value lies within ``DETERMINED_Z`` standard errors of zero (an
    estimate of many standard errors is determined, whatever the range)."""
    width = params.to_display(physical_ranges(params, ranges))
    shown = params.to_display(np.nan_to_num(np.asarray(std_si, dtype=float), nan=0.0))
    z = np.zeros(len(names))
    if values_si is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            z = np.abs(np.asarray(values_si, dtype=float)) / np.asarray(std_si, dtype=float)
    out = []
    for name, s, sh, rng, unit, zk in zip(
        names, std_si, shown, width, params.display_units(), z, strict=True
    ):
        if np.isfinite(s) and sh > WEAK_FRACTION * rng and not zk >= DETERMINED_Z:
            out.append({"name": name, "std": float(sh), "prior_range": float(rng), "unit": unit})
    return out


def correlation_matrix(covariance: np.ndarray) -> np.ndarray:
    """cov_ij / (std_i std_j); NaN where a standard deviation is zero."""
    cov = np.asarray(covariance, dtype=float)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        return cov / np.outer(std, std)


def collinear_groups(
    names: tuple[str, ...], covariance: np.ndarray, threshold: float = COLLINEAR_R
) -> list[list[str]]:
    """Groups of parameters joined by correlations above ``threshold`` (union of pairs)."""
    corr = correlation_matrix(covariance)
    parent = list(range(len(names)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    linked = np.argwhere(np.triu(np.abs(np.nan_to_num(corr)) > threshold, k=1))
    for i, j in linked:
        parent[root(int(i))] = root(int(j))
    groups: dict[int, list[str]] = {}
    for i in {int(k) for pair in linked for k in pair}:
        groups.setdefault(root(i), []).append(names[i])
    return sorted((sorted(g) for g in groups.values()), key=lambda g: (-len(g), g))
