"""What an identification is given: a dataset bound to the mechanism (its readings in the
model's order, checked against its names, units, frame and strokes), and the model from files."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.data.dataset import Dataset, DatasetError
from calib.data.orientation_columns import mean_rotation
from calib.fit.kinds import PoseState
from calib.fit.model import CalibrationModel
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.workspace import check_command_strokes

FRAMES = ("base", "tracker")


@dataclass(frozen=True)
class Observations:
    """A dataset bound to a mechanism: SI commands (P, A) and measured targets (P, T, 3).

    ``pose_ids`` (the dataset's pose ids, as text) and ``target_names`` label the rows of
    ``commands`` and the targets of ``measured``, in that order; None when not known.
    ``frame`` is "base" (readings in the machine's base frame) or "tracker" (in the
    tracker's own frame: a registration is estimated with the parameters)."""

    commands: np.ndarray
    measured: np.ndarray
    pose_ids: tuple[str, ...] | None = None
    target_names: tuple[str, ...] | None = None
    frame: str = "base"
    state: PoseState | None = None  # directions, time, temperature (the offset kinds')
    # 6-DoF probes: the targets' frames (P, T, 3, 3) in the readings' frame, NaN for targets
    # without one, and the weight of their rows (m / rad, calib.fit.probe_rows)
    rotations: np.ndarray | None = None
    orientation_weight_m: float | None = None


def bind_dataset(mech: Mechanism, dataset: Dataset) -> Observations:
    """Check a dataset against the mechanism (model, names, units, frame, strokes) and order
    it like it."""
    if dataset.model != mech.name:
        raise DatasetError(
            f"dataset is for model '{dataset.model}', but the mechanism is '{mech.name}'"
        )
    if dataset.frame not in FRAMES:
        raise DatasetError(
            f"dataset frame is '{dataset.frame}'; it must be 'base' (readings in the machine's "
            "base frame) or 'tracker' (in the tracker's own frame, registered in the fit)"
        )
    dataset.check_against(mech.actuator_names, mech.target_names)
    ds = dataset.reordered(mech.actuator_names, mech.target_names)
    for name, unit, slide in zip(
        ds.actuator_names, ds.actuator_units, mech.actuator_is_slide, strict=True
    ):
        expected = "mm" if slide else "deg"
        if unit != expected:
            kind = "prismatic" if slide else "revolute"
            raise DatasetError(
                f"actuator '{name}' is {kind} in the model, so its unit must be '{expected}', "
                f"but the dataset declares '{unit}'"
            )
    check_command_strokes(mech, np.asarray(ds.commands), ds.pose_labels)
    rotations = None
    if ds.orientations is not None and ds.oriented.any():
        rotations = np.full((ds.n_poses, ds.n_targets, 3, 3), np.nan)
        rotations[:, ds.oriented] = mean_rotation(ds.orientations[:, ds.oriented])
    return Observations(
        commands=np.array(ds.commands),
        measured=np.array(ds.measured),
        pose_ids=tuple(str(p) for p in ds.pose_ids.tolist()),
        target_names=tuple(ds.target_names),
        frame=ds.frame,
        state=PoseState.of(ds),
        rotations=rotations,
    )


def model_from_files(mjcf: str, params_file: str) -> CalibrationModel:
    """A calibration model from an MJCF file and an error-model TOML file."""
    mech = Mechanism.from_xml(mjcf)
    return CalibrationModel(mech, load_parameter_set(params_file, mech.model))
