"""Scoring readings from another day, another tracker station: ``verify --register``.

A tracker moved between the calibration and the test day reports in a frame the result's
registration knows nothing of. ``verify --register`` fits only the rigid registration of
these readings (6 degrees of freedom, no machine parameter) for each side on its own: the
nominal model's predictions for "before", the calibrated model's for "after", each by the
closed-form least-squares rigid fit (:func:`calib.fit.registration.initial_registration`).
With ``--register-set NAME`` the registration is fitted on the rows of that set and the other
rows are scored, so that no scored row chooses its own frame.

Without ``--register``, :func:`station_check` compares the after-side errors under the
result's own registration with the result's residual: beyond :data:`STATION_RATIO` times it,
verify does not score (exit 4), says how much a fresh registration explains, and points to
``--register``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.fit.model import CalibrationModel
from calib.fit.position_error import error_norms, stats_mm
from calib.fit.registration import Registration, initial_registration
from calib.fit.verify import Verification, orientation_source, probe_deg, score_side

STATION_RATIO = 10.0  # "an order of magnitude" beyond the result's residual
# below a micrometre a residual says nothing of the station (a tracker's resolution); a
# noise-free fit's residual is floored there so that its held-out poses are not refused
RESIDUAL_FLOOR_MM = 1e-3


def verify_registered(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    measured: np.ndarray,
    pose_ids: np.ndarray,
    fit_rows: np.ndarray | None = None,
    fit_name: str | None = None,
    rotations: np.ndarray | None = None,
) -> Verification:
    """Before and after errors of ``measured`` (P, T, 3), each side in its own rigid
    registration fitted to its own predictions on the poses ``fit_rows`` (bool (P,); None:
    all of them). The poses scored are those not in ``fit_rows`` (all when it is None)."""
    fresh = CalibrationModel(model.nominal, model.params)
    x0, values = np.zeros(model.n_parameters), np.asarray(values, dtype=float)
    pred0, pred1 = fresh.predict(x0, commands), fresh.predict(values, commands)
    nominal, after = pred0.targets, pred1.targets
    n = len(commands)
    fit = np.ones(n, dtype=bool) if fit_rows is None else np.asarray(fit_rows, dtype=bool)
    scored = np.ones(n, dtype=bool) if fit_rows is None else ~fit
    reg_before = initial_registration(measured[fit], nominal[fit])
    reg_after = initial_registration(measured[fit], after[fit])
    if fit_rows is None:
        where = f"the {n} scored poses themselves"
    else:
        where = f"the {int(fit.sum())} poses of set '{fit_name}' (not scored)"
    note = (
        "registered afresh (--register): only the rigid registration of these readings was "
        f"fitted (6 DoF, no machine parameter), for each side on its own, on {where}"
    )
    rot = None if rotations is None else rotations[scored]
    ori0 = probe_deg(fresh, x0, pred0.qpos[scored], rot, reg_before)
    ori1 = probe_deg(fresh, values, pred1.qpos[scored], rot, reg_after)
    return Verification(
        pose_ids=np.asarray(pose_ids)[scored],
        target_names=model.nominal.target_names,
        before=score_side(
            model.nominal, reg_before.to_base(measured[scored]), nominal[scored], ori0
        ),
        after=score_side(model.nominal, reg_after.to_base(measured[scored]), after[scored], ori1),
        note=note,
        registration_before=reg_before,
        registration_after=reg_after,
        orientation_source=orientation_source(ori0, measured),
    )


@dataclass(frozen=True)
class StationCheck:
    """The after-side RMS under the result's registration against the result's residual,
    and the RMS a fresh registration of these readings leaves (mm)."""

    rms_result_registration_mm: float
    residual_rms_mm: float
    rms_registered_afresh_mm: float

    @property
    def scale_mm(self) -> float:
        return max(self.residual_rms_mm, RESIDUAL_FLOOR_MM)

    @property
    def ratio(self) -> float:
        return self.rms_result_registration_mm / self.scale_mm

    @property
    def refused(self) -> bool:
        return self.ratio > STATION_RATIO

    @property
    def afresh_explains(self) -> bool:
        """A fresh rigid registration brings the error back within the order of magnitude."""
        return self.rms_registered_afresh_mm <= STATION_RATIO * self.scale_mm

    def message(self) -> str:
        floor = "" if self.scale_mm == self.residual_rms_mm else f", taken as {self.scale_mm:g} mm"
        head = (
            f"with the result's own registration these readings are off by RMS "
            f"{self.rms_result_registration_mm:.4f} mm, {self.ratio:.1f} times the result's "
            f"residual ({self.residual_rms_mm:.4f} mm{floor}); a rigid registration fitted to them "
            f"alone leaves RMS {self.rms_registered_afresh_mm:.4f} mm"
        )
        if self.afresh_explains:
            why = ": these readings look like another tracker station"
        else:
            ratio = self.rms_registered_afresh_mm / self.scale_mm
            why = (
                f", still {ratio:.1f} times the residual: another station, and a machine "
                "that does not match the result either"
            )
        return (
            f"{head}{why}. Not scored: run verify again with --register (the registration "
            "fitted afresh on these readings) or --register-set NAME (fitted on the rows of "
            "set NAME, the others scored)"
        )


def station_check(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    measured: np.ndarray,
    registration: Registration,
    residual_rms_mm: float,
) -> StationCheck:
    """How far the result's ``registration`` leaves these tracker-frame readings."""
    fresh = CalibrationModel(model.nominal, model.params)
    after = fresh.predict(np.asarray(values, dtype=float), commands).targets
    with_result = stats_mm(error_norms(registration.to_base(measured), after)).rms_mm
    afresh = initial_registration(measured, after)
    refit = stats_mm(error_norms(afresh.to_base(measured), after)).rms_mm
    return StationCheck(with_result, float(residual_rms_mm), refit)
