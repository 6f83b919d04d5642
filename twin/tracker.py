"""Laser-tracker simulator and a rigid-body pose noise model.

All quantities are SI (metres, radians). Random draws come only from the
``np.random.Generator`` passed in.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.rotations import matrix_from_rotvec, matrix_from_rpy

Array = NDArray[np.float64]

NoiseKind = Literal["gaussian", "uniform", "none"]
_NOISE_KINDS = ("gaussian", "uniform", "none")

_LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "μm": 1e-6, "nm": 1e-9}
_NUMBER = r"(?:\d+(?:\.\d*)?|\.\d+)(?:e[+-]?\d+)?"
_TERM_RE = re.compile(
    rf"\s*(?P<num>{_NUMBER})\s*(?P<unit>ppm|mm|um|µm|μm|nm|m)?\s*(?P<per>/\s*m(?![a-zµμ]))?\s*"
)


def _check_magnitude(value: float, name: str) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"{name} must be finite and non-negative, got {value!r}")
    return value


def _format_length(metres: float) -> str:
    return f"{metres * 1e6:.6g} um"


@dataclass(frozen=True)
class TrackerNoise:
    """Per-coordinate noise of a laser-tracker reading.

    The noise magnitude at a point a distance ``d`` (metres) from the tracker head is
    ``s = constant_m + per_metre * d``:

    * ``"gaussian"``: each coordinate gets independent zero-mean normal noise with
      standard deviation ``s``;
    * ``"uniform"``: each coordinate gets independent noise uniform on ``[-s, s]``
      (standard deviation ``s / sqrt(3)``);
    * ``"none"``: readings are exact; the magnitudes are ignored.

    ``constant_m`` is in metres, ``per_metre`` is dimensionless (``5e-6`` = 5 um/m).
    """

    kind: NoiseKind
    constant_m: float
    per_metre: float

    def __post_init__(self) -> None:
        if self.kind not in _NOISE_KINDS:
            raise ValueError(f"noise kind must be one of {_NOISE_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "constant_m", _check_magnitude(self.constant_m, "constant_m"))
        object.__setattr__(self, "per_metre", _check_magnitude(self.per_metre, "per_metre"))

    @classmethod
    def none(cls) -> TrackerNoise:
        """Noise-free readings."""
        return cls("none", 0.0, 0.0)

    @classmethod
    def from_spec(cls, text: str) -> TrackerNoise:
        """Parse e.g. ``"10 um + 5 um/m"``, ``"0.005 mm"``, ``"gaussian 10um+5um/m"``,
        ``"uniform 0.02 mm"`` or ``"none"``.

        An optional leading kind (default ``gaussian``) is followed by ``+``-separated
        terms: a length (units m, mm, um/µm, nm) or a per-metre term (length unit
        followed by ``/m``, or ``ppm``). Each term type may appear at most once.
        """
        if not isinstance(text, str):
            raise ValueError(f"noise spec must be a string, got {type(text).__name__}")
        s = text.strip().lower()
        if not s:
            raise ValueError("empty noise spec")
        kind: NoiseKind = "gaussian"
        m = re.match(r"(gaussian|uniform|none)\b\s*", s)
        if m:
            kind = m.group(1)  # type: ignore[assignment]
            s = s[m.end() :]
        if kind == "none":
            if s:
                raise ValueError(f"noise spec {text!r}: 'none' takes no magnitudes")
            return cls.none()
        if not s:
            raise ValueError(f"noise spec {text!r} has no magnitude (e.g. '10 um + 5 um/m')")

        constant: float | None = None
        per_metre: float | None = None
        pos = 0
        while True:
            t = _TERM_RE.match(s, pos)
            if t is None or t.end() == pos:
                raise ValueError(
                    f"cannot parse noise spec {text!r} near {s[pos:]!r}; "
                    "expected e.g. '10 um + 5 um/m'"
                )
            value = float(t.group("num"))
            unit, per = t.group("unit"), t.group("per")
            if unit is None:
                raise ValueError(f"noise spec {text!r}: missing unit after {t.group('num')!r}")
            if unit == "ppm":
                if per:
                    raise ValueError(f"noise spec {text!r}: 'ppm/m' is not a valid unit")
                unit_per, scaled = True, value * 1e-6
            else:
                unit_per, scaled = bool(per), value * _LENGTH_UNITS[unit]
            if unit_per:
                if per_metre is not None:
                    raise ValueError(f"noise spec {text!r} has more than one per-metre term")
                per_metre = scaled
            else:
                if constant is not None:
                    raise ValueError(f"noise spec {text!r} has more than one constant term")
                constant = scaled
            pos = t.end()
            if pos == len(s):
                break
            if s[pos] != "+":
                raise ValueError(
                    f"cannot parse noise spec {text!r} near {s[pos:]!r}; terms are joined by '+'"
                )
            pos += 1
        return cls(kind, constant or 0.0, per_metre or 0.0)

    def describe(self) -> str:
        """Human-readable form, accepted by :meth:`from_spec`."""
        if self.kind == "none":
            return "none"
        parts = [_format_length(self.constant_m)]
        if self.per_metre:
            parts.append(f"{_format_length(self.per_metre)}/m")
        return f"{self.kind} " + " + ".join(parts)

    def magnitude(self, distance: ArrayLike) -> Array:
        """``constant_m + per_metre * distance`` (sigma or half-width); 0 for ``none``."""
        d = np.asarray(distance, dtype=float)
        if self.kind == "none":
            return np.zeros_like(d)
        return self.constant_m + self.per_metre * d

    def std(self, distance: ArrayLike) -> Array:
        """Per-coordinate standard deviation at the given distance(s) from the head."""
        mag = self.magnitude(distance)
        return mag / math.sqrt(3.0) if self.kind == "uniform" else mag

    def sample(
        self, distance: ArrayLike, shape: tuple[int, ...], rng: np.random.Generator
    ) -> Array:
        """Noise of ``shape`` (..., 3); ``distance`` must broadcast against ``shape[:-1]``."""
        if self.kind == "none":
            return np.zeros(shape)
        mag = self.magnitude(distance)[..., None]
        if self.kind == "gaussian":
            return rng.standard_normal(shape) * mag
        return rng.uniform(-1.0, 1.0, size=shape) * mag


# ----------------------------------------------------------------- air and the distance scale

_C_TO_K_EDLEN = 0.0036610  # 1/K, the modified Edlen temperature term


def air_refractive_index(
    temperature_C: float,
    pressure_Pa: float = 101325.0,
    water_vapour_Pa: float = 1170.0,
    wavelength_m: float = 633e-9,
) -> float:
    """Phase refractive index of air, modified Edlen equation (Birch and Downs, Metrologia 30
    (1993) 155 and 31 (1994) 315): dry air of standard composition, water vapour subtracted.

    ``water_vapour_Pa``: partial pressure of water vapour (1170 Pa is 50 % humidity at 20 C).
    At 20 C, 101325 Pa, 633 nm it gives n - 1 = 2.718e-4 dry and 2.714e-4 at 1170 Pa; dn/dT
    is -0.93e-6 / K, dn/dp +2.7e-9 / Pa, and 117 Pa (10 % humidity) more vapour -0.04e-6.
    """
    t = float(temperature_C)
    sigma2 = (1e-6 / float(wavelength_m)) ** 2  # (1/um)^2
    ns = 1e-8 * (8342.54 + 2406147.0 / (130.0 - sigma2) + 15998.0 / (38.9 - sigma2))
    p = float(pressure_Pa)
    ntp = p * ns / 96095.43 * (1.0 + 1e-8 * (0.601 - 0.00972 * t) * p) / (1.0 + _C_TO_K_EDLEN * t)
    f = float(water_vapour_Pa)
    return 1.0 + ntp - f * (3.7345 - 0.0401 * sigma2) * 1e-10


@dataclass(frozen=True)
class AirCompensation:
    """A tracker's air compensation against the air its beam really crosses.

    The interferometer / ADM measures optical path n_true d; the tracker divides it by the
    index it computes from its weather input, n_set, and reports d n_true / n_set. A tracker
    compensating for ``set_C`` in a hall at ``hall_C`` (a station left at 20 C, a sensor in
    the sun, a hall that warmed after the reading) has the relative distance scale error
    n(hall) / n(set) - 1, about -0.93 ppm per kelvin the hall is warmer (Edlen): 20 C set in a
    23 C hall reads distances 2.8 ppm short, 5.6 um at 2 m. Pressure and humidity are the
    same in both (their own errors are smaller: 1 hPa is 0.27 ppm, 10 % humidity 0.04 ppm).
    """

    hall_C: float = 23.0
    set_C: float = 20.0
    pressure_Pa: float = 101325.0
    water_vapour_Pa: float = 1170.0  # 50 % humidity at 20 C; the same absolute humidity in both
    wavelength_m: float = 633e-9  # HeNe interferometer; an ADM near 800 nm differs by <1 %

    def __post_init__(self) -> None:
        for key in ("hall_C", "set_C", "pressure_Pa", "water_vapour_Pa", "wavelength_m"):
            v = float(getattr(self, key))
            if not math.isfinite(v):
                raise ValueError(f"{key} must be finite, got {v!r}")
            object.__setattr__(self, key, v)
        if not -40.0 <= self.hall_C <= 60.0 or not -40.0 <= self.set_C <= 60.0:
            raise ValueError(
                f"air temperatures must lie in [-40, 60] C, got {self.hall_C}, {self.set_C}"
            )
        if not 5e4 <= self.pressure_Pa <= 1.2e5:
            raise ValueError(f"pressure_Pa must lie in [50000, 120000], got {self.pressure_Pa}")
        if not 0.0 <= self.water_vapour_Pa <= 2e4:
            raise ValueError(f"water_vapour_Pa must lie in [0, 20000], got {self.water_vapour_Pa}")
        if not 2e-7 <= self.wavelength_m <= 2e-6:
            raise ValueError(f"wavelength_m must lie in [0.2, 2] um, got {self.wavelength_m}")

    def index(self, temperature_C: float) -> float:
        return air_refractive_index(
            temperature_C, self.pressure_Pa, self.water_vapour_Pa, self.wavelength_m
        )

    @property
    def scale_error(self) -> float:
        """Relative error of every reported distance from the head (dimensionless)."""
        if self.hall_C == self.set_C:
            return 0.0
        return self.index(self.hall_C) / self.index(self.set_C) - 1.0


def _default_tracker_noise() -> TrackerNoise:
    return TrackerNoise("gaussian", 10e-6, 5e-6)


@dataclass(frozen=True)
class Tracker:
    """A laser tracker at ``position_m`` in the machine base frame.

    A reading of a target at ``x`` is ``h + (1 + scale_error) * (x - h) + noise`` with
    ``h`` the head position: ``scale_error`` is a relative scale error of the instrument
    (distances from the head are multiplied by ``1 + scale_error``); the noise follows
    :class:`TrackerNoise` evaluated at the true distance ``|x - h|``. Each reading is
    repeated ``repeats`` times with independent noise. ``air`` (optional) adds the scale
    error of a wrong air compensation (:class:`AirCompensation`); the two scales multiply.
    """

    position_m: tuple[float, float, float] = (1.2, 0.0, 0.3)
    noise: TrackerNoise = field(default_factory=_default_tracker_noise)
    scale_error: float = 0.0
    repeats: int = 1
    # orientation of the tracker's own frame in the base frame (R = Rz Ry Rx of these), for
    # readings reported in the tracker's frame (its origin is the head)
    rotation_rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    air: AirCompensation | None = None

    def __post_init__(self) -> None:
        pos = tuple(float(v) for v in np.asarray(self.position_m, dtype=float).reshape(-1))
        if len(pos) != 3 or not all(math.isfinite(v) for v in pos):
            raise ValueError(f"position_m must be 3 finite numbers, got {self.position_m!r}")
        object.__setattr__(self, "position_m", pos)
        if not isinstance(self.noise, TrackerNoise):
            raise ValueError(f"noise must be a TrackerNoise, got {type(self.noise).__name__}")
        scale = float(self.scale_error)
        if not math.isfinite(scale) or scale <= -1.0:
            raise ValueError(f"scale_error must be finite and > -1, got {self.scale_error!r}")
        object.__setattr__(self, "scale_error", scale)
        if isinstance(self.repeats, bool) or int(self.repeats) != self.repeats:
            raise ValueError(f"repeats must be an integer, got {self.repeats!r}")
        if self.repeats < 1:
            raise ValueError(f"repeats must be >= 1, got {self.repeats}")
        object.__setattr__(self, "repeats", int(self.repeats))
        rpy = tuple(float(v) for v in np.asarray(self.rotation_rpy_rad, dtype=float).reshape(-1))
        if len(rpy) != 3 or not all(math.isfinite(v) for v in rpy):
            raise ValueError(f"rotation_rpy_rad must be 3 finite angles, got {rpy!r}")
        object.__setattr__(self, "rotation_rpy_rad", rpy)
        if self.air is not None and not isinstance(self.air, AirCompensation):
            raise ValueError(f"air must be an AirCompensation, got {type(self.air).__name__}")

    @property
    def total_scale_error(self) -> float:
        """The instrument's scale error with the air compensation's, (1 + s)(1 + s_air) - 1."""
        if self.air is None:
            return self.scale_error
        return (1.0 + self.scale_error) * (1.0 + self.air.scale_error) - 1.0

    @property
    def base_from_tracker(self) -> tuple[Array, Array]:
        """(R, t) with p_base = R p_tracker + t: the tracker's pose in the base frame."""
        return matrix_from_rpy(np.array(self.rotation_rpy_rad)), np.array(self.position_m)

    def in_own_frame(self, points_base: ArrayLike) -> Array:
        """Base-frame points (..., 3) as this tracker reports them in its own frame."""
        rot, t = self.base_from_tracker
        return (np.asarray(points_base, dtype=float) - t) @ rot

    def _points(self, points: ArrayLike) -> Array:
        x = np.asarray(points, dtype=float)
        if x.ndim < 1 or x.shape[-1] != 3:
            raise ValueError(f"points must have shape (..., 3), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("points contain non-finite values (NaN or inf)")
        return x

    def distance(self, points: ArrayLike) -> Array:
        """Distance (metres) from the tracker head to each point, shape (...,)."""
        x = self._points(points)
        return np.linalg.norm(x - np.asarray(self.position_m), axis=-1)

    def noise_sigma(self, points: ArrayLike, *, averaged: bool = False) -> Array:
        """Per-coordinate standard deviation of a reading at each point, shape (...,).

        With ``averaged=True`` it is that of :meth:`measure_averaged` (divided by
        ``sqrt(repeats)``).
        """
        sigma = self.noise.std(self.distance(points))
        return sigma / math.sqrt(self.repeats) if averaged else sigma

    def _exact_and_noise(self, points: ArrayLike, rng: np.random.Generator) -> tuple[Array, Array]:
        x = self._points(points)
        rel = x - np.asarray(self.position_m)
        dist = np.linalg.norm(rel, axis=-1)
        scale = self.total_scale_error
        exact = x + scale * rel if scale else x
        noise = self.noise.sample(dist[..., None], (*x.shape[:-1], self.repeats, 3), rng)
        return exact, noise

    def measure(self, points: ArrayLike, rng: np.random.Generator) -> Array:
        """Readings (..., repeats, 3) of exact target positions ``points`` (..., 3)."""
        exact, noise = self._exact_and_noise(points, rng)
        return exact[..., None, :] + noise

    def measure_averaged(self, points: ArrayLike, rng: np.random.Generator) -> Array:
        """Mean of :meth:`measure` over the repeats, shape (..., 3)."""
        exact, noise = self._exact_and_noise(points, rng)
        return exact + np.mean(noise, axis=-2)


@dataclass(frozen=True)
class PoseNoise:
    """Noise on a measured rigid-body pose ``(R, p)``.

    ``p_noisy = p + dp`` and ``R_noisy = matrix_from_rotvec(dtheta) @ R`` (rotation
    error expressed in the base frame), with each component of ``dp`` and ``dtheta``
    drawn independently: uniform on ``[-position_m, position_m]`` and
    ``[-rotation_rad, rotation_rad]`` for ``"uniform"``, or normal with those standard
    deviations for ``"gaussian"``. Defaults: 0.02 mm and 0.004 deg, uniform.
    """

    kind: Literal["uniform", "gaussian"] = "uniform"
    position_m: float = 0.02e-3
    rotation_rad: float = math.radians(0.004)

    def __post_init__(self) -> None:
        if self.kind not in ("uniform", "gaussian"):
            raise ValueError(f"pose noise kind must be 'uniform' or 'gaussian', got {self.kind!r}")
        object.__setattr__(self, "position_m", _check_magnitude(self.position_m, "position_m"))
        object.__setattr__(
            self, "rotation_rad", _check_magnitude(self.rotation_rad, "rotation_rad")
        )

    def _draw(self, shape: tuple[int, ...], scale: float, rng: np.random.Generator) -> Array:
        if self.kind == "gaussian":
            return rng.standard_normal(shape) * scale
        return rng.uniform(-1.0, 1.0, size=shape) * scale

    def perturb(self, R: ArrayLike, p: ArrayLike, rng: np.random.Generator) -> tuple[Array, Array]:
        """Noisy copies of rotations ``R`` (..., 3, 3) and positions ``p`` (..., 3)."""
        rot = np.asarray(R, dtype=float)
        pos = np.asarray(p, dtype=float)
        if rot.ndim < 2 or rot.shape[-2:] != (3, 3):
            raise ValueError(f"R must have shape (..., 3, 3), got {rot.shape}")
        if pos.shape != rot.shape[:-1]:
            raise ValueError(f"p must have shape {rot.shape[:-1]} to match R, got {pos.shape}")
        if not (np.all(np.isfinite(rot)) and np.all(np.isfinite(pos))):
            raise ValueError("R or p contain non-finite values (NaN or inf)")
        dp = self._draw(pos.shape, self.position_m, rng)
        dtheta = self._draw(pos.shape, self.rotation_rad, rng)
        return matrix_from_rotvec(dtheta) @ rot, pos + dp
