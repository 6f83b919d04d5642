"""Whether a fit is a success: converged, and a residual the declared accuracy explains.

A fit that did not converge, or whose residual is far above the tracker accuracy the user
declared, must not look like success. The verdict compares the 3D RMS residual per reading
with the noise a tracker of the declared accuracy gives, sqrt(3) sigma for sigma per
coordinate, and fails beyond ``max_ratio`` times that (default 10: unmodelled effects of a
well-built machine stay within a few times the noise; a wrong unit, a swapped column or a
mislabelled target give tens to thousands). The command line turns the verdict into its
exit code:

    0  success: converged, residual within max_ratio of the noise
    2  bad input: the data or model files could not be used (the message names the cause)
    3  the fit did not converge (which criterion failed is said)
    4  the data does not fit the model: residual beyond max_ratio of the noise, estimates
       beyond a plausible size (50 mm, 20 deg by default: the fit bent the geometry to fit
       bad data), or too many readings rejected as outliers (the likely cause is said when
       the data shows it)
    5  compensate: some desired poses are out of reach (each is named; the others written)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_POOR_FIT = 4
EXIT_UNREACHABLE = 5
DEFAULT_MAX_RATIO = 10.0
# an estimate beyond these is not a manufacturing or assembly error but a fit that went
# astray (a length error of 5 cm on a machine built to tenths of a millimetre)
PLAUSIBLE_MM = 50.0
PLAUSIBLE_DEG = 20.0
ASSUMED_SIGMA_MM = 0.05  # per coordinate: a laser tracker at a few metres plus repeatability


@dataclass(frozen=True)
class Accuracy:
    """Tracker accuracy per coordinate (mm) and where the number came from."""

    sigma_mm: float
    source: str  # "command line", "dataset sidecar", "repeats", "assumed"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma_mm) and self.sigma_mm > 0):
            raise ValueError(f"tracker accuracy must be a positive number, got {self.sigma_mm!r}")


def declared_accuracy(cli_sigma_mm: float | None, tracker_info: dict[str, Any] | None) -> Accuracy:
    """The command line's ``--sigma-mm``, else the sidecar's ``tracker.sigma_mm``, else an
    assumed 0.05 mm (said so in the output)."""
    if cli_sigma_mm is not None:
        return Accuracy(float(cli_sigma_mm), "command line")
    value = (tracker_info or {}).get("sigma_mm")
    if value is not None:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"the sidecar's tracker.sigma_mm must be a number, got {value!r}")
        return Accuracy(float(value), "dataset sidecar")
    return Accuracy(ASSUMED_SIGMA_MM, "assumed")


@dataclass(frozen=True)
class Verdict:
    status: str  # "ok", "not_converged", "poor_fit"
    exit_code: int
    residual_rms_mm: float  # 3D per reading
    noise_rms_mm: float  # sqrt(3) sigma: the 3D RMS the declared accuracy explains
    ratio: float
    accuracy: Accuracy
    message: str
    hints: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> bool:
        return self.exit_code == EXIT_OK

    def as_dict(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "exit_code": self.exit_code,
            "residual_rms_mm": self.residual_rms_mm,
            "noise_rms_mm": self.noise_rms_mm,
            "residual_to_noise": self.ratio,
            "sigma_mm": self.accuracy.sigma_mm,
            "sigma_source": self.accuracy.source,
            "message": self.message,
            "hints": list(self.hints),
        }


def judge_fit(
    residual_rms_mm: float,
    converged: bool,
    convergence_message: str,
    accuracy: Accuracy,
    max_ratio: float = DEFAULT_MAX_RATIO,
    hints: tuple[str, ...] = (),
    implausible: tuple[str, ...] = (),
) -> Verdict:
    """The verdict on a fit with 3D RMS residual ``residual_rms_mm`` per reading;
    ``implausible`` names estimates beyond a plausible size (see :func:`implausible_estimates`)."""
    if not (math.isfinite(max_ratio) and max_ratio >= 1):
        raise ValueError(f"max_ratio must be a number >= 1, got {max_ratio!r}")
    noise = math.sqrt(3.0) * accuracy.sigma_mm
    ratio = residual_rms_mm / noise if math.isfinite(residual_rms_mm) else math.inf
    where = f"tracker accuracy {accuracy.sigma_mm:g} mm per coordinate ({accuracy.source})"

    def verdict(status: str, code: int, message: str) -> Verdict:
        return Verdict(status, code, residual_rms_mm, noise, ratio, accuracy, message, hints)

    if not converged:
        return verdict(
            "not_converged",
            EXIT_NOT_CONVERGED,
            f"FAILED: the fit did not converge ({convergence_message or 'no criterion met'}); "
            f"residual {residual_rms_mm:.4f} mm RMS",
        )
    if ratio > max_ratio:
        return verdict(
            "poor_fit",
            EXIT_POOR_FIT,
            f"FAILED: residual {residual_rms_mm:.4f} mm RMS is {ratio:.1f} times the "
            f"{noise:.4f} mm that the {where} explains (limit {max_ratio:g} times)",
        )
    if implausible:
        shown = ", ".join(implausible[:5]) + (" ..." if len(implausible) > 5 else "")
        return verdict(
            "poor_fit",
            EXIT_POOR_FIT,
            f"FAILED: {len(implausible)} estimate(s) beyond a plausible size ({shown}): the fit "
            "bent the geometry to follow data the model cannot explain",
        )
    tail = (
        "consistent with the tracker noise"
        if ratio <= 2.0
        else "above the tracker noise: unmodelled effects remain (try `calib diagnose`)"
    )
    return verdict(
        "ok",
        EXIT_OK,
        f"ok: residual {residual_rms_mm:.4f} mm RMS, {ratio:.2f} times the {noise:.4f} mm "
        f"of the {where}: {tail}",
    )


def implausible_estimates(
    names: tuple[str, ...],
    display_values: Any,
    is_angle: Any,
    plausible_mm: float = PLAUSIBLE_MM,
    plausible_deg: float = PLAUSIBLE_DEG,
) -> tuple[str, ...]:
    """Parameters whose estimate (mm or deg) exceeds the plausible size of its kind."""
    out = []
    for name, v, angle in zip(names, display_values, is_angle, strict=True):
        limit, unit = (plausible_deg, "deg") if angle else (plausible_mm, "mm")
        if not math.isfinite(float(v)) or abs(float(v)) > limit:
            out.append(f"{name} = {float(v):+.1f} {unit}")
    return tuple(out)
