"""Whether a fit is a success, and what the user must fix when it is not.

A fit is refused only for what a user must fix: it did not converge, the data look wrong
(readings in other units, two actuator columns exchanged, target labels permuted: named by
calib.data.hints; too many outliers, in calib.fit.workflow), estimates that are implausible *and*
well determined (the data exclude a plausible size at three standard errors: the model or
the data are not the machine's), or a residual no calibrated machine leaves (above
``PLAUSIBLE_RESIDUAL_FRACTION`` of the machine's reach: another machine's data, the wrong
model file). A residual above the declared tracker accuracy with none of these is the normal
case on a real machine (its unmodelled effects leave 10-20 times the tracker noise): the
verdict is a success that says how far above the noise the residual is, whether it is
structured, and that ``pkm-calib diagnose`` is the next step. ``--max-ratio`` turns such a
residual into a failure for a user who wants that gate. Exit codes:

    0  success (the residual's size against the noise is said)
    2  bad input: the data or model files could not be used (the message names the cause)
    3  the fit did not converge (which criterion failed is said), no data error named
    4  the data do not fit the model: a likely data error named (converged or not), too
       many outliers, implausible well-determined estimates, an implausible residual, or a
       residual above an explicit ``--max-ratio``
    5  compensate: some desired poses are out of reach (each is named; the others written)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_POOR_FIT = 4
EXIT_UNREACHABLE = 5
EXIT_WORKER_LOST = 6  # a worker process was killed (most often for lack of memory)
DEFAULT_MAX_RATIO: float | None = None  # no gate on the residual's size unless asked
# an estimate beyond these is not a manufacturing or assembly error but a fit that went
# astray (a length error of 5 cm on a machine built to tenths of a millimetre)
PLAUSIBLE_MM = 50.0
PLAUSIBLE_DEG = 20.0
PLAUSIBLE_PPM = 2e5  # an actuator gain 20 % off is a wrong factor, not a calibration error
# a drive softer than 100 N m/rad (revolute) or 1e4 N/m (prismatic), under a payload of up to
# 100 kg for the per-kg products, is a wrong model, not a joint compliance
PLAUSIBLE_COMPLIANCE = {"deg/(kN m)": 600.0, "mm/kN": 100.0, "deg/(kN m) kg": 6e4, "mm/kN kg": 1e4}
PLAUSIBLE_RESIDUAL_FRACTION = 0.01  # of the machine's reach, 3D RMS after calibration
ASSUMED_SIGMA_MM = 0.05  # per coordinate: a laser tracker at a few metres plus repeatability
# a tracker, motion capture or measuring arm is accurate to a few millimetres at worst; a
# declared accuracy beyond this is a unit or typing mistake that would pass any fit
MAX_SIGMA_MM = 100.0


@dataclass(frozen=True)
class Accuracy:
    """Tracker accuracy per coordinate (mm) and where the number came from."""

    sigma_mm: float
    source: str  # "command line", "dataset sidecar", "repeats", "assumed"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma_mm) and self.sigma_mm > 0):
            raise ValueError(f"tracker accuracy must be a positive number, got {self.sigma_mm!r}")
        if self.sigma_mm > MAX_SIGMA_MM:
            raise ValueError(
                f"tracker accuracy {self.sigma_mm:g} mm per coordinate ({self.source}) is beyond "
                f"{MAX_SIGMA_MM:g} mm: no measuring system of a machine is that coarse (the "
                "value is in millimetres)"
            )


def declared_accuracy(
    cli_sigma_mm: float | None,
    tracker_info: dict[str, Any] | None,
    repeats_sigma_mm: float | None = None,
) -> Accuracy:
    """The noise level per coordinate of one reading, by the one rule identify and diagnose
    share: declared (the command line's ``--sigma-mm``, else the sidecar's
    ``tracker.sigma_mm``), else the scatter of the repeat readings (``repeats_sigma_mm``),
    else an assumed ``ASSUMED_SIGMA_MM`` (said so in the output)."""
    if cli_sigma_mm is not None:
        return Accuracy(float(cli_sigma_mm), "command line")
    value = (tracker_info or {}).get("sigma_mm")
    if value is not None:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"the sidecar's tracker.sigma_mm must be a number, got {value!r}")
        return Accuracy(float(value), "dataset sidecar")
    if repeats_sigma_mm is not None and repeats_sigma_mm > 0:
        return Accuracy(float(repeats_sigma_mm), "repeats")
    return Accuracy(ASSUMED_SIGMA_MM, "assumed")


def noise_rule(cli_sigma_mm: float | None, dataset: Any) -> Accuracy:
    """:func:`declared_accuracy` of a Dataset: its sidecar, then its repeats."""
    spread = repeats_sigma_mm(dataset.repeat_std, dataset.n_repeats)
    return declared_accuracy(cli_sigma_mm, dataset.tracker, spread)


def repeats_sigma_mm(repeat_std_m: np.ndarray | None, n_repeats: int) -> float | None:
    """The pooled per-coordinate scatter of one reading over its repeats (mm), if any."""
    if repeat_std_m is None or n_repeats < 2:
        return None
    s = np.asarray(repeat_std_m, dtype=float)
    s = s[np.isfinite(s)]
    return float(np.sqrt(np.mean(s**2))) * 1e3 if s.size and np.any(s > 0) else None


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
    max_ratio: float | None = DEFAULT_MAX_RATIO,
    hints: tuple[str, ...] = (),
    implausible: tuple[str, ...] = (),
    reach_mm: float | None = None,
    structure: str = "",
) -> Verdict:
    """The verdict on a fit with 3D RMS residual ``residual_rms_mm`` per reading.

    ``hints``: likely data errors (calib.data.hints); ``implausible``: estimates beyond a
    plausible size that the data determine well (see :func:`implausible_estimates`);
    ``reach_mm``: the machine's size, for the plausible residual; ``structure``: what the
    residual follows, in words (said when it is above the noise)."""
    if max_ratio is not None and not (math.isfinite(max_ratio) and max_ratio >= 1):
        raise ValueError(f"max_ratio must be a number >= 1, got {max_ratio!r}")
    noise = math.sqrt(3.0) * accuracy.sigma_mm
    ratio = residual_rms_mm / noise if math.isfinite(residual_rms_mm) else math.inf
    where = f"tracker accuracy {accuracy.sigma_mm:g} mm per coordinate ({accuracy.source})"
    size = (
        f"residual {residual_rms_mm:.4f} mm RMS is {ratio:.1f} times the {noise:.4f} mm that "
        f"the {where} explains"
    )

    def verdict(status: str, code: int, message: str) -> Verdict:
        return Verdict(status, code, residual_rms_mm, noise, ratio, accuracy, message, hints)

    if hints:  # a named data error is the cause, whether or not the fit converged on it
        tail = "" if converged else f"; the fit did not converge ({convergence_message})"
        return verdict("poor_fit", EXIT_POOR_FIT, f"FAILED: the data look wrong; {size}{tail}")
    if not converged:
        return verdict(
            "not_converged",
            EXIT_NOT_CONVERGED,
            f"FAILED: the fit did not converge ({convergence_message or 'no criterion met'}); "
            f"residual {residual_rms_mm:.4f} mm RMS"
            + (
                "; a fit still moving at its iteration limit may need more: --max-iterations N"
                if "iteration limit" in convergence_message
                else ""
            ),
        )
    if implausible:
        shown = ", ".join(implausible[:5]) + (" ..." if len(implausible) > 5 else "")
        return verdict(
            "poor_fit",
            EXIT_POOR_FIT,
            f"FAILED: {len(implausible)} estimate(s) beyond a plausible size that the data "
            f"determine well ({shown}): the model or the data are not this machine's",
        )
    limit = None if reach_mm is None else PLAUSIBLE_RESIDUAL_FRACTION * reach_mm
    if limit is not None and residual_rms_mm > limit:
        return verdict(
            "poor_fit",
            EXIT_POOR_FIT,
            f"FAILED: residual {residual_rms_mm:.4f} mm RMS is more than "
            f"{PLAUSIBLE_RESIDUAL_FRACTION:.0%} of the machine's reach ({reach_mm:.0f} mm): no "
            "calibrated machine leaves that; check that the data are this machine's, in the "
            "frame and units the sidecar declares",
        )
    if max_ratio is not None and ratio > max_ratio:
        return verdict("poor_fit", EXIT_POOR_FIT, f"FAILED: {size} (limit {max_ratio:g} times)")
    if ratio <= 2.0:
        tail = "consistent with the tracker noise"
    else:
        found = f"; {structure}" if structure else ""
        tail = (
            f"more than the tracker noise{found}. Real machines leave 10-20 times their "
            "tracker noise after a geometric fit: the geometry is identified; `pkm-calib "
            "diagnose` tests which effect the model lacks"
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
    units: Any,
    display_std: Any = None,
) -> tuple[str, ...]:
    """Parameters whose estimate (in its display unit: "mm", "deg", "ppm", a compliance's;
    a bool is read as angle or not) exceeds the plausible size of its kind by more than three
    of its standard errors (``display_std``, same units; None: by any amount); a unit without
    a known size (an offset kind's rate or strain) is not judged."""
    limits = {"mm": PLAUSIBLE_MM, "deg": PLAUSIBLE_DEG, "ppm": PLAUSIBLE_PPM}
    limits.update(PLAUSIBLE_COMPLIANCE)
    out = []
    std = [0.0] * len(names) if display_std is None else list(display_std)
    for name, v, s, unit in zip(names, display_values, std, units, strict=True):
        if isinstance(unit, (bool, np.bool_)):
            unit = "deg" if unit else "mm"
        limit = limits.get(unit)
        if limit is None:  # a rate or a strain of the offset kinds: no plausible size known
            continue
        s = float(s) if math.isfinite(float(s)) else 0.0
        if not math.isfinite(float(v)) or abs(float(v)) - 3.0 * s > limit:
            out.append(f"{name} = {float(v):+.1f} +- {s:.1f} {unit}")
    return tuple(out)
