"""Choosing the rows of a dataset by its ``set`` column (calibration, test, ...)."""

from __future__ import annotations

import dataclasses

import numpy as np

from calib.data.dataset import Dataset, DatasetError

CALIBRATION = "calibration"


def select_set(dataset: Dataset, name: str | None, purpose: str) -> tuple[Dataset, str]:
    """The poses of set ``name``; with ``name`` None, the rows marked ``calibration``, or all
    rows when no row is so marked. Returns the selection and a sentence saying which.

    ``purpose`` names the use in messages ("calibration", "verification")."""
    sets = [str(s) for s in dataset.sets]
    known = sorted(set(sets))
    if name is None:
        if CALIBRATION in known and purpose == "calibration":
            name = CALIBRATION
        else:
            return dataset, (
                f"all {dataset.n_poses} poses used for {purpose} (sets in the file: {known})"
            )
    mask = np.array([s == name for s in sets])
    if not mask.any():
        raise DatasetError(
            f"the dataset has no pose in set '{name}' (its sets: {known}): nothing to use for "
            f"{purpose}"
        )
    picked = subset(dataset, mask)
    return picked, (
        f"{picked.n_poses} of {dataset.n_poses} poses (set '{name}') used for {purpose}"
    )


def subset(dataset: Dataset, mask: np.ndarray) -> Dataset:
    """The poses where ``mask`` is true, every per-pose field cut alike."""
    mask = np.asarray(mask, dtype=bool)

    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a)[mask]

    return dataclasses.replace(
        dataset,
        pose_ids=cut(dataset.pose_ids),
        sets=cut(dataset.sets),
        commands=cut(dataset.commands),
        readings=cut(dataset.readings),
        order=cut(dataset.order),
        time_s=cut(dataset.time_s),
        temperature_c=cut(dataset.temperature_c),
        direction=cut(dataset.direction),
        commanded_poses=cut(dataset.commanded_poses),
        orientations=cut(dataset.orientations),
    )
