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
from calib.fit.probe_rows import target_rotations
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
    # where the orientation error comes from: "probe" (6-DoF readings), "pattern" (the rigid
    # fit of three or more targets) or "" (none)
    orientation_source: str = ""

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
            "orientation_from": {
                "probe": "the 6-DoF probes' frames (RMS over the probes per pose)",
                "pattern": "the rigid fit of the model's target pattern onto the readings",
            }.get(self.orientation_source),
            "note": self.note,
        }

    def rows(self) -> list[dict]:
        """One row per reading, for the per-pose CSV (with a probe: the pose's orientation
        error beside each of its readings)."""
        out = []
        probe = self.orientation_source == "probe"
        for p, pid in enumerate(self.pose_ids):
            for t, name in enumerate(self.target_names):
                row = {
                    "pose_id": int(pid),
                    "target": name,
                    "before_mm": float(self.before.per_reading_m[p, t] * 1e3),
                    "after_mm": float(self.after.per_reading_m[p, t] * 1e3),
                }
                if probe:
                    row["before_deg"] = float(self.before.orientation_deg[p])
                    row["after_deg"] = float(self.after.orientation_deg[p])
                out.append(row)
        return out


def _orientation_deg(local: np.ndarray, measured: np.ndarray, predicted: np.ndarray):
    if measured.shape[1] < 3:
        return None
    r_meas, _ = fit_rigid_transform(local, measured)
    r_pred, _ = fit_rigid_transform(local, predicted)
    return np.degrees(rotation_angle(np.swapaxes(r_pred, -1, -2) @ r_meas))


def score_side(
    mech: Mechanism,
    measured_base: np.ndarray,
    predicted: np.ndarray,
    probe_deg: np.ndarray | None = None,
) -> Side:
    """The errors of readings ``measured_base`` (P, T, 3) against a model's ``predicted``
    targets: per reading, their statistics, and the tool's orientation error per pose (that
    of the probes, ``probe_deg``, when given; else of three or more targets' pattern)."""
    norms = error_norms(measured_base, predicted)
    local = mech.target_local() if measured_base.shape[1] >= 3 else None
    ori = None if local is None else _orientation_deg(local, measured_base, predicted)
    return Side(stats_mm(norms), norms, ori if probe_deg is None else probe_deg)


def probe_deg(
    model: CalibrationModel,
    values: np.ndarray,
    qpos: np.ndarray,
    rotations: np.ndarray | None,
    registration: Registration | None,
) -> np.ndarray | None:
    """The probes' orientation error per pose (P,), degrees (RMS over the probes of the angle
    between the measured and the predicted frame), or None without probes. ``rotations``
    (P, T, 3, 3) in the readings' frame, NaN for targets without one."""
    if rotations is None:
        return None
    oriented = np.flatnonzero(np.isfinite(rotations).all(axis=(0, 2, 3)))
    if not oriented.size:
        return None
    pred = target_rotations(model.mechanism(values), qpos, oriented)
    meas = rotations[:, oriented]
    meas = meas if registration is None else registration.rotation @ meas
    angle = rotation_angle(meas @ np.swapaxes(pred, -1, -2))
    return np.degrees(np.sqrt(np.mean(angle * angle, axis=1)))


def nominal_fit_registration(
    model: CalibrationModel, commands: np.ndarray, measured: np.ndarray
) -> Registration:
    """The nominal model's registration of tracker-frame readings ``measured`` (P, T, 3) at
    ``commands``: the rigid fit of the readings to the nominal predictions, the "before"'s
    frame in every command (verify, compensate)."""
    fresh = CalibrationModel(model.nominal, model.params)
    predicted = fresh.predict(np.zeros(model.n_parameters), commands).targets
    return initial_registration(measured, predicted)


def verify(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    measured: np.ndarray,
    pose_ids: np.ndarray,
    registration_after: Registration | None = None,
    calibration_set: tuple[np.ndarray, np.ndarray] | None = None,
    registration_before: Registration | None = None,
    rotations: np.ndarray | None = None,
) -> Verification:
    """Before (nominal) and after (``values``) errors of readings ``measured`` (P, T, 3).

    With ``registration_after`` the readings are in the tracker's frame; the nominal
    registration is then fitted on ``calibration_set`` = (commands, readings) of the
    calibration (or given as ``registration_before``: calib.fit.workflow.nominal_registration,
    the one every command uses), or, without either, on these readings (said in ``note``)."""
    x0, values = np.zeros(model.n_parameters), np.asarray(values, dtype=float)
    fresh = CalibrationModel(model.nominal, model.params)
    fresh.bind_state(model.state)  # of these readings (the offset kinds read it)
    pred0 = fresh.predict(x0, commands)
    nominal = pred0.targets
    pred1 = fresh.predict(values, commands)
    after = pred1.targets
    if registration_after is None:
        before_base = after_base = measured
        note = "readings in the machine's base frame"
    else:
        if registration_before is not None or calibration_set is not None:
            reg0 = registration_before
            if reg0 is None:
                reg0 = nominal_fit_registration(model, *calibration_set)
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
    reg_before = None if registration_after is None else reg0
    ori0 = probe_deg(fresh, x0, pred0.qpos, rotations, reg_before)
    ori1 = probe_deg(fresh, values, pred1.qpos, rotations, registration_after)
    return Verification(
        pose_ids=np.asarray(pose_ids),
        target_names=model.nominal.target_names,
        before=score_side(model.nominal, before_base, nominal, ori0),
        after=score_side(model.nominal, after_base, after, ori1),
        note=note,
        registration_before=reg_before,
        registration_after=registration_after,
        orientation_source=orientation_source(ori0, measured),
    )


def orientation_source(probe: np.ndarray | None, measured: np.ndarray) -> str:
    if probe is not None:
        return "probe"
    return "pattern" if measured.shape[1] >= 3 else ""
