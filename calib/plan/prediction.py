"""The twin predicts the campaign: the held-out accuracy a program will give, before measuring.

For each draw, a truth is drawn from the error model's ranges: every parameter uniform within
plus or minus its physical range (calib.fit.prior.physical_ranges: 1 mm, 0.1 deg, 1 % for a
gain ...; ``truth_scale`` times that), the readings of the program's calibration poses are
simulated through forward kinematics of the model with that truth injected (the calibration
model's own prediction: twin.kinematics.batch.forward_batch on the injected mechanism, gains
and compliances included), with Gaussian noise of ``sigma`` per coordinate, and identified as
``pkm-calib identify`` does (robust, weak directions kept at zero where cross-validation says
so). The held-out error is what ``pkm-calib verify`` reports on the test poses: the 3D distance
between a simulated reading (noise included) and the identified model's prediction. Its
median and 90th percentile over the test poses, per draw, are the prediction; the spread over
draws is its uncertainty. Beside it, the same of the model's own error (the identified
model's prediction against the drawn truth, no reading noise): what a compensation through it
would leave, and the sharper comparison of two pose sets when the tracker noise dominates.

This simulates truths, and that is its purpose: "calib never sees the truth" is about the
pipeline on a user's readings, which this is not. A planning prediction draws possible truths
from the error model (it never sees a real one) to say what a campaign of these poses would
give on a machine whose errors are of that size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.exceptions import CalibError
from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations
from calib.fit.prior import physical_ranges
from twin.exceptions import TwinError


@dataclass(frozen=True)
class Prediction:
    """Held-out accuracy over draws for one pose set: per draw (NaN where the fit failed)."""

    n: int
    kind: str  # "plan" or "random"
    median_mm: np.ndarray  # (D,) held-out error as verify reports it
    p90_mm: np.ndarray  # (D,)
    model_median_mm: np.ndarray  # (D,) the identified model against the truth
    model_p90_mm: np.ndarray  # (D,)

    def stats(self) -> dict:
        ok = np.isfinite(self.median_mm)
        out: dict = {"n": self.n, "kind": self.kind, "draws": len(ok), "failed": int((~ok).sum())}
        for key in ("median_mm", "p90_mm", "model_median_mm", "model_p90_mm"):
            v = getattr(self, key)[ok]
            out[key] = float(np.mean(v)) if len(v) else float("nan")
            out[key.replace("_mm", "_std_mm")] = (
                float(np.std(v, ddof=1)) if len(v) > 1 else float("nan")
            )
            out["per_draw_" + key] = [float(x) for x in getattr(self, key)]
        return out


def draw_truth(model: CalibrationModel, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """One value per parameter (SI), uniform within +-``scale`` times its physical range."""
    ranges = physical_ranges(model.params)
    return rng.uniform(-1.0, 1.0, size=len(ranges)) * ranges * scale


def readings(
    model: CalibrationModel,
    truth: np.ndarray,
    commands: np.ndarray,
    sigma_m: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Simulated tracker readings (P, T, 3) (m) of ``commands`` on the machine ``truth``."""
    targets = model.predict(truth, commands).targets
    return targets + rng.normal(0.0, sigma_m, size=targets.shape)


def held_out(
    model: CalibrationModel,
    truth: np.ndarray,
    cal: np.ndarray,
    test: np.ndarray,
    sigma_m: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray] | None:
    """3D errors (mm) of every test reading after identifying from ``cal``, and of the
    identified model against the truth there; None if the identification fails (too few
    poses for the outlier check, a model that does not close at the estimate)."""
    measured = readings(model, truth, cal, sigma_m, rng)
    true_test = model.predict(truth, test).targets
    held = true_test + rng.normal(0.0, sigma_m, size=true_test.shape)
    try:
        res = identify(model, Observations(cal, measured), unidentifiable="fix", subspace="auto")
        predicted = model.predict(res.values, test).targets
    except (CalibError, TwinError):
        return None
    norm = np.linalg.norm
    return norm(held - predicted, axis=-1).ravel() * 1e3, norm(
        true_test - predicted, axis=-1
    ).ravel() * 1e3


def predict(
    model: CalibrationModel,
    truths: list[np.ndarray],
    cal_sets: list[np.ndarray],
    test: np.ndarray,
    sigma_m: float,
    seed: int,
    kind: str,
) -> Prediction:
    """Held-out accuracy per draw; ``cal_sets[d]`` the calibration commands of draw ``d``
    (one plan for all, or a fresh random set each)."""
    rows = []
    for d, (truth, cal) in enumerate(zip(truths, cal_sets, strict=True)):
        rng = np.random.default_rng([seed, d, len(cal), kind == "plan"])
        errs = held_out(model, truth, cal, test, sigma_m, rng)
        rows.append(
            [np.nan] * 4
            if errs is None
            else [f(e) for e in errs for f in (np.median, lambda v: np.percentile(v, 90))]
        )
    a = np.array(rows, dtype=float).reshape(len(rows), 4)
    return Prediction(len(cal_sets[0]), kind, a[:, 0], a[:, 1], a[:, 2], a[:, 3])
