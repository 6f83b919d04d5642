"""From the truth twin to a Dataset file, exactly what a real machine would hand over."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from calib.data import Dataset, read_dataset, write_dataset
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.tracker import PoseNoise, Tracker


def machine_fields(mech: Mechanism) -> dict:
    """What a Dataset says of its machine: the model's name, its actuators and their units,
    its targets."""
    return {
        "model": mech.name,
        "actuator_names": mech.actuator_names,
        "actuator_units": tuple("mm" if s else "deg" for s in mech.actuator_is_slide),
        "target_names": mech.target_names,
    }


def measured_dataset(
    truth: Mechanism,
    commands: np.ndarray,
    poses: np.ndarray,
    set_name: str,
    tracker: Tracker,
    rng: np.random.Generator,
    pose_noise: PoseNoise | None = None,
    first_pose_id: int = 0,
    notes: str = "",
) -> Dataset:
    """Measure the truth twin at ``commands`` and package the readings as a Dataset."""
    m = measure(truth, commands, tracker, rng, pose_noise)
    n = len(commands)
    tracker_info = {
        "position_mm": [v * 1e3 for v in tracker.position_m],
        "noise": tracker.noise.describe(),
        "repeats": tracker.repeats,
    }
    if pose_noise is not None:
        tracker_info["pose_noise"] = {
            "kind": pose_noise.kind,
            "position_mm": pose_noise.position_m * 1e3,
            "rotation_deg": float(np.degrees(pose_noise.rotation_rad)),
        }
    return Dataset(
        **machine_fields(truth),
        frame="base",
        pose_ids=np.arange(first_pose_id, first_pose_id + n),
        sets=np.array([set_name] * n),
        commands=commands,
        readings=m.readings,
        order=np.arange(n),
        commanded_poses=poses,
        tracker=tracker_info,
        notes=notes,
    )


def tracker_frame_dataset(
    truth: Mechanism,
    tracker: Tracker,
    commands: np.ndarray,
    n_cal: int,
    sigma_mm: float,
    rng: np.random.Generator,
    effects: Sequence = (),
    notes: str = "",
) -> Dataset:
    """What a tracker standing in its own frame exports of the truth (with its physical
    ``effects``): readings in the tracker's frame, a set column (``n_cal`` calibration rows,
    then test rows) and the accuracy the export declares (``sigma_mm``)."""
    n = len(commands)
    m = measure(truth, commands, tracker, rng, effects=effects)
    return Dataset(
        **machine_fields(truth),
        frame="tracker",
        pose_ids=np.arange(1, n + 1),
        sets=np.array(["calibration"] * n_cal + ["test"] * (n - n_cal)),
        commands=commands,
        readings=tracker.in_own_frame(m.readings),
        order=np.arange(n),
        tracker={"noise": tracker.noise.describe(), "sigma_mm": sigma_mm},
        notes=notes,
    )


def through_file(dataset: Dataset, path: Path, expected_model: str) -> Dataset:
    """Write the dataset and read it back, so calibration sees only what the file holds."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_dataset(dataset, path)
    return read_dataset(path, expected_model=expected_model)
