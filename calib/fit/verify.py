"""Scoring a calibration on any dataset: the error before (nominal) and after (identified).

Both use the project's one metric, the 3D position error of each reading (RMS, mean, max),
plus the tool's orientation error per pose when the dataset has three or more targets (the
rotation that carries the model's target pattern onto the measured one). For readings in
the tracker's frame, "after" uses the registration identified with the parameters and
"before" a registration fitted with the nominal kinematics on the same calibration set, so
that neither side is scored with a frame fitted to the poses it is scored on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.fit.model import CalibrationModel
from calib.fit.position_error import PositionErrorStats, error_norms, stats_mm
from calib.fit.registration import Registration, initial_registration
from twin.mechanism import Mechanism
from twin.rigid_fit import fit_rigid_transform
from twin.rotations import rotation_angle


@dataclass(frozen=True)
class Side:
    """One side of the comparison."""

    position: PositionErrorStats
    per_reading_m: np.ndarray  # (P, T)
    orientation_deg: np.ndarray | None  # (P,) or None with fewer than 3 targets

    def as_dict(self) -> dict:
        out: dict = dict(self.position.as_dict())
        if self.orientation_deg is not None:
            o = self.orientation_deg
            out["orientation"] = {
                "rms_deg": float(np.sqrt(np.mean(o * o))),
                "mean_deg": float(np.mean(o)),
                "max_deg": float(np.max(o)),
            }
        return out

    def line(self, label: str) -> str:
        """One printed line: ``label``, the 3D position error per reading, the orientation's."""
        text = f"{label}: 3D position error per reading {self.position.describe()}"
        if self.orientation_deg is not None:
            o = self.orientation_deg
            text += f"; orientation RMS {np.sqrt(np.mean(o * o)):.4f} deg, max {o.max():.4f} deg"
        return text


@dataclass(frozen=True)
class Verification:
    pose_ids: np.ndarray
    target_names: tuple[str, ...]
    before: Side
    after: Side
    note: str
    # the base-from-tracker frames each side was scored in (None: readings in the base frame)
    registration_before: Registration | None = None
    registration_after: Registration | None = None

    @property
    def n_poses(self) -> int:
        return len(self.pose_ids)

    def as_dict(self) -> dict:
        return {
            "n_poses": self.n_poses,
            "n_readings": self.after.position.n,
            "metric": "3D position error per reading |p_measured - p_model| (mm)",
            "before": self.before.as_dict(),
            "after": self.after.as_dict(),
            "note": self.note,
        }

    def rows(self) -> list[dict]:
        """One row per reading, for the per-pose CSV."""
        out = []
        for p, pid in enumerate(self.pose_ids):
            for t, name in enumerate(self.target_names):
                out.append(
                    {
                        "pose_id": int(pid),
                        "target": name,
                        "before_mm": float(self.before.per_reading_m[p, t] * 1e3),
                        "after_mm": float(self.after.per_reading_m[p, t] * 1e3),
                    }
                )
        return out


def _orientation_deg(local: np.ndarray, measured: np.ndarray, predicted: np.ndarray):
    if measured.shape[1] < 3:
        return None
    r_meas, _ = fit_rigid_transform(local, measured)
    r_pred, _ = fit_rigid_transform(local, predicted)
    return np.degrees(rotation_angle(np.swapaxes(r_pred, -1, -2) @ r_meas))


def score_side(mech: Mechanism, measured_base: np.ndarray, predicted: np.ndarray) -> Side:
    """The errors of readings ``measured_base`` (P, T, 3) against a model's ``predicted``
    targets: per reading, their statistics, and the tool's orientation error per pose."""
    norms = error_norms(measured_base, predicted)
    local = mech.target_local() if measured_base.shape[1] >= 3 else None
    ori = None if local is None else _orientation_deg(local, measured_base, predicted)
    return Side(stats_mm(norms), norms, ori)


def _side(model: CalibrationModel, measured_base: np.ndarray, predicted: np.ndarray) -> Side:
    return score_side(model.nominal, measured_base, predicted)


def verify(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    measured: np.ndarray,
    pose_ids: np.ndarray,
    registration_after: Registration | None = None,
    calibration_set: tuple[np.ndarray, np.ndarray] | None = None,
) -> Verification:
    """Before (nominal) and after (``values``) errors of readings ``measured`` (P, T, 3).

    With ``registration_after`` the readings are in the tracker's frame; the nominal
    registration is then fitted on ``calibration_set`` = (commands, readings) of the
    calibration, or, without it, on these readings (said in ``note``)."""
    x0 = np.zeros(model.n_parameters)
    fresh = CalibrationModel(model.nominal, model.params)
    nominal = fresh.predict(x0, commands).targets
    after = fresh.predict(np.asarray(values, dtype=float), commands).targets
    if registration_after is None:
        before_base = after_base = measured
        note = "readings in the machine's base frame"
    else:
        if calibration_set is not None:
            c_cmd, c_meas = calibration_set
            reg0 = initial_registration(c_meas, fresh.predict(x0, c_cmd).targets)
            note = (
                "tracker frame: 'after' with the registration identified with the parameters, "
                "'before' with one fitted to the nominal model on the calibration set"
            )
        else:
            reg0 = initial_registration(measured, nominal)
            note = (
                "tracker frame: the calibration set was not available, so 'before' uses a "
                "registration fitted to the nominal model on these readings (it favours "
                "'before')"
            )
        before_base = reg0.to_base(measured)
        after_base = registration_after.to_base(measured)
    return Verification(
        pose_ids=np.asarray(pose_ids),
        target_names=model.nominal.target_names,
        before=_side(model, before_base, nominal),
        after=_side(model, after_base, after),
        note=note,
        registration_before=None if registration_after is None else reg0,
        registration_after=registration_after,
    )
