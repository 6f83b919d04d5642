"""``verify --result``'s choice of frame: the result's registration, or one fitted afresh.

Readings from the calibration day are scored in the registration identified with the result.
Readings from another day may come from another tracker station: ``--register`` fits the
rigid registration of these readings alone (both sides, on the scored rows), ``--register-set
NAME`` on the rows of set NAME with the others scored. Without either, tracker-frame readings
that the result's registration leaves an order of magnitude beyond the result's residual are
not scored (exit 4), with the numbers and the advice (calib.fit.verify_register).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from calib.data import CalibrationResult, Dataset, DatasetError, select_set, subset
from calib.fit import (
    EXIT_POOR_FIT,
    CalibrationModel,
    Verification,
    bind_dataset,
    station_check,
    verify_registered,
    verify_result,
)


def add_options(ver: argparse.ArgumentParser) -> None:
    ver.add_argument(
        "--register",
        action="store_true",
        help="readings from another tracker station (another day): fit only the rigid "
        "registration of these readings (6 DoF, no machine parameter) for each side, on the "
        "scored rows, instead of using the result's",
    )
    ver.add_argument(
        "--register-set",
        metavar="NAME",
        help="as --register, the registration fitted on the rows of set NAME; the other rows "
        "(of --set, if given) are scored",
    )
    ver.add_argument(
        "--iso9283",
        action="store_true",
        help="ISO 9283 pose accuracy AP and repeatability RP per commanded pose, before and "
        "after, from repeated readings (the 'repeat' column, or poses with identical "
        "commands); --out then writes the report (JSON, CSV per pose, PNG)",
    )


def _registered(
    model: CalibrationModel, loaded: CalibrationResult, dataset: Dataset, args
) -> tuple[Verification, str]:
    values = loaded.values_for(model.params)
    name = args.register_set
    sets = np.array([str(s) for s in dataset.sets])
    if name is None:
        picked, selection = select_set(dataset, args.set, "verification")
        obs = bind_dataset(model.nominal, picked)
        v = verify_registered(
            model, values, obs.commands, obs.measured, picked.pose_ids, rotations=obs.rotations
        )
        return v, selection
    if name not in set(sets):
        raise DatasetError(
            f"--register-set {name}: the dataset has no pose in that set (its sets: "
            f"{sorted(set(sets))})"
        )
    scored = sets != name if args.set is None else sets == args.set
    if args.set is not None and not scored.any():
        raise DatasetError(f"--set {args.set}: the dataset has no pose in that set")
    if args.set == name or not (scored & (sets != name)).any():
        raise DatasetError(
            f"--register-set {name}: no other rows are left to score (give another --set)"
        )
    picked = subset(dataset, scored | (sets == name))
    obs = bind_dataset(model.nominal, picked)
    fit = np.array([str(s) == name for s in picked.sets])
    v = verify_registered(
        model,
        values,
        obs.commands,
        obs.measured,
        picked.pose_ids,
        fit_rows=fit,
        fit_name=name,
        rotations=obs.rotations,
    )
    selection = (
        f"{v.n_poses} of {dataset.n_poses} poses scored, registered on the "
        f"{int(fit.sum())} poses of set '{name}'"
    )
    return v, selection


def verification(
    model: CalibrationModel, loaded: CalibrationResult, dataset: Dataset, args
) -> tuple[Verification, str] | int:
    """The verification ``args`` ask for, or EXIT_POOR_FIT when tracker-frame readings look
    like another station and no ``--register`` was given (the reason printed)."""
    if args.register or args.register_set:
        return _registered(model, loaded, dataset, args)
    residual = loaded.data.get("residual_rms_mm")
    if dataset.frame == "tracker" and loaded.registration is not None and residual is not None:
        picked, _ = select_set(dataset, args.set, "verification")
        obs = bind_dataset(model.nominal, picked)
        check = station_check(
            model,
            loaded.values_for(model.params),
            obs.commands,
            obs.measured,
            loaded.registration,
            float(residual),
        )
        if check.refused:
            print(f"ANOTHER STATION? {check.message()}", file=sys.stderr)
            return EXIT_POOR_FIT
    return verify_result(model, loaded, dataset, args.set)
