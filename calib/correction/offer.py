"""Whether a residual correction is offered: fitted, cross-validated, guarded, judged (on one
BLAS thread, as the diagnosis: the same digits whatever the machine's thread count).

The correction is fitted to what the geometry and the named effects leave (physics first)
on the calibration poses whose readings were all kept, its length scale and regularisation
chosen by K-fold cross-validation over poses (the diagnosis's folds: blocks of the
measurement order). It is offered only when

* it lowers the cross-validated mean square by more than the noise moves it (three standard
  deviations of the mean square of pure noise over those rows: 3 s^2 sqrt(2 / n), the
  diagnosis's rule), with the guard applied to the held-out poses;
* it lowers the test set's RMS when one is given;
* it raises the largest 3D error per reading (on the test set when given, else held out in
  the cross-validation) by no more than the noise of a 3D reading (sqrt(3) s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.correction.correction import ResidualCorrection, guard_radius
from calib.correction.kernel_ridge import cross_validate, fit_kernel_ridge
from twin.kinematics.structure import on_one_blas_thread


def stats(e: np.ndarray) -> dict[str, float]:
    """RMS, mean and max (mm) of the 3D error per reading of residual rows (N, T*3), m."""
    norms = np.linalg.norm(np.asarray(e).reshape(len(e), -1, 3), axis=2).ravel()
    if norms.size == 0:
        return {"rms_mm": 0.0, "mean_mm": 0.0, "max_mm": 0.0}
    return {
        "rms_mm": float(np.sqrt(np.mean(norms**2))) * 1e3,
        "mean_mm": float(np.mean(norms)) * 1e3,
        "max_mm": float(np.max(norms)) * 1e3,
    }


@dataclass(frozen=True)
class Offer:
    correction: ResidualCorrection | None  # None: too few poses to cross-validate
    offered: bool
    reason: str  # from the numbers
    numbers: dict = field(default_factory=dict)  # cv / test: before, after (stats)
    test_std_mm: np.ndarray | None = None  # predictive std per test pose
    test_inside: np.ndarray | None = None


@on_one_blas_thread
def fit_and_judge(
    x: np.ndarray,
    residual: np.ndarray,
    complete: np.ndarray,
    labels: np.ndarray,
    sigma_m: float,
    names: tuple[str, ...],
    units: tuple[str, ...],
    test: tuple[np.ndarray, np.ndarray] | None = None,
) -> Offer:
    """The correction of ``residual`` (N, T*3) over features ``x`` (N, d) on the ``complete``
    poses, cross-validated over the folds ``labels``, and whether it is offered (see the
    module). ``test``: (features, residual) of held-out poses."""
    x, y = np.asarray(x, float)[complete], np.asarray(residual, float)[complete]
    labels = np.asarray(labels)[complete]
    n_targets = y.shape[1] // 3
    if len(np.unique(labels)) < 2 or len(y) < 10:
        return Offer(None, False, f"{len(y)} complete poses are too few to cross-validate")
    cv = cross_validate(x, y, labels)
    radius = guard_radius(cv)
    inside = cv.distance <= radius
    guarded = np.where(inside[:, None], cv.after, cv.before)
    numbers = {
        "cv": {"before": stats(cv.before), "after": stats(guarded)},
        "cv_poses_inside": int(inside.sum()),
        "cv_poses": len(y),
    }
    kr = fit_kernel_ridge(x, y, cv.length_scale, cv.ratio)
    numbers["length_scale"], numbers["noise_to_signal_ratio"] = cv.length_scale, cv.ratio
    corr = ResidualCorrection(kr, radius, names, units, n_targets)
    ms_before, ms_after = np.mean(cv.before**2), np.mean(guarded**2)
    noise_ms = 3.0 * sigma_m**2 * np.sqrt(2.0 / y.size)
    why: list[str] = []
    if not ms_before - ms_after > noise_ms:
        why.append(
            f"it lowers the cross-validated RMS per coordinate from {np.sqrt(ms_before) * 1e3:.4g}"
            f" to {np.sqrt(ms_after) * 1e3:.4g} mm, not beyond the noise"
        )
    judged, where = numbers["cv"], "held out in the cross-validation"
    std = inside_t = None
    if test is not None:
        pred = corr.predict(test[0])
        after = np.asarray(test[1]) - pred["mean"]
        judged = numbers["test"] = {"before": stats(test[1]), "after": stats(after)}
        numbers["test_poses_inside"] = int(pred["inside"].sum())
        numbers["test_poses"] = len(after)
        where = "on the test set"
        std, inside_t = pred["std"] * 1e3, pred["inside"]
        if not judged["after"]["rms_mm"] < judged["before"]["rms_mm"]:
            why.append(
                f"it does not lower the test RMS ({judged['before']['rms_mm']:.4g} -> "
                f"{judged['after']['rms_mm']:.4g} mm)"
            )
    tol_mm = np.sqrt(3.0) * sigma_m * 1e3
    if judged["after"]["max_mm"] > judged["before"]["max_mm"] + tol_mm:
        why.append(
            f"it raises the largest error {where} from {judged['before']['max_mm']:.4g} to "
            f"{judged['after']['max_mm']:.4g} mm, more than the noise ({tol_mm:.3g} mm)"
        )
    b, a = judged["before"], judged["after"]
    if why:
        reason = "not offered: " + "; ".join(why)
    else:
        reason = (
            f"offered: {where} RMS {b['rms_mm']:.4g} -> {a['rms_mm']:.4g} mm, max "
            f"{b['max_mm']:.4g} -> {a['max_mm']:.4g} mm; within the calibrated region "
            f"(standardised distance <= {radius:.3g}, {numbers['cv_poses_inside']} of "
            f"{len(y)} poses held out in the cross-validation)"
        )
    numbers["guard_radius"] = radius
    final = ResidualCorrection(kr, radius, names, units, n_targets, {**numbers, "reason": reason})
    return Offer(final, not why, reason, numbers, std, inside_t)
