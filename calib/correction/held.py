"""The residual correction where a calibration is used: held in a fit, added to a prediction.

A diagnosis file (``diagnose --out``) or a result file (``identify --with``) carries the
correction as its ``residual_correction`` block. ``identify --with`` holds it: the readings
less the correction (rotated into the tracker's frame by the geometric fit's registration
for tracker-frame data) are what the geometry and any named effect are refitted to. Every
user of a result (verify, compensate, export) then predicts a reading as the identified
model's prediction plus the correction at the pose's features, inside the calibrated region
only: :func:`corrected_targets`.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from calib.correction.correction import CorrectionFileError, ResidualCorrection, pose_features
from calib.fit.model import CalibrationModel
from twin.kinematics.structure import on_one_blas_thread

KEY = "residual_correction"


def correction_in(data: dict[str, Any] | None, model: CalibrationModel, where: str):
    """The correction of a diagnosis's or result's content ``data`` (None without one),
    checked against ``model``'s machine and reflectors."""
    block = (data or {}).get(KEY)
    if block is None:
        return None
    corr = ResidualCorrection.from_dict(block, where, model.nominal.name)
    want = model.nominal.n_actuators + (3 if corr.with_position else 0)
    if len(corr.names) != want or corr.n_targets != model.nominal.n_targets:
        raise CorrectionFileError(
            f"{where}: the residual correction has {len(corr.names)} features and "
            f"{corr.n_targets} targets, the model {want} and {model.nominal.n_targets}"
        )
    return corr


def correction_in_file(path: str | Path, model: CalibrationModel) -> ResidualCorrection | None:
    """The correction of the diagnosis file ``path`` (None without one)."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None  # load_effect names what is wrong with the file
    return correction_in(data if isinstance(data, dict) else None, model, str(p))


def features_at(
    corr: ResidualCorrection, model: CalibrationModel, values: np.ndarray, commands: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The correction's features at ``commands`` and the model's predicted targets (N, T, 3)
    there (the tool position is their mean)."""
    targets = model.predict(values, commands).targets
    return pose_features(commands, targets.mean(axis=1) if corr.with_position else None), targets


@on_one_blas_thread
def corrected_targets(
    corr: ResidualCorrection, model: CalibrationModel, values: np.ndarray, commands: np.ndarray
) -> dict[str, np.ndarray]:
    """The model's targets (N, T, 3) at ``commands`` plus the correction (base frame, m),
    and the correction's ``std`` (N,) m, ``inside`` (N,) and ``distance`` (N,)."""
    x, targets = features_at(corr, model, values, commands)
    pred = corr.predict(x)
    return {**pred, "targets": targets + pred["mean"].reshape(targets.shape)}


@on_one_blas_thread
def held_dataset(dataset, corr: ResidualCorrection, model: CalibrationModel, values, registration):
    """``dataset`` with every reading less the correction at its pose (features from the
    model at ``values``; in the tracker frame through ``registration``; at a pose that
    carries the correction, the correction fitted without it), and the count of poses
    inside the calibrated region."""
    x, _ = features_at(corr, model, values, dataset.commands)
    pred = corr.predict_held_out(x)
    shift = pred["mean"].reshape(dataset.n_poses, dataset.n_targets, 3)
    if registration is not None:
        shift = registration.to_tracker(shift) - registration.to_tracker(np.zeros(3))
    readings = dataset.readings - shift[:, :, None, :]
    return dataclasses.replace(dataset, readings=readings), int(pred["inside"].sum())
