"""Scoring a model as it is: ``verify --model M.xml`` without ``--result``.

An exported calibrated model (``pkm-calib export``), a vendor's model or any MJCF is scored on
readings with the project's one metric, the 3D position error per reading (RMS, mean, max),
and the tool's orientation error per pose with three or more targets. Readings in the
tracker's frame are registered by a rigid fit of the model's predictions to the readings of
the calibration set (the rows marked 'calibration'), so that the scored rows do not choose
their own frame; a file without such rows (or scoring the calibration rows themselves) is
registered on the scored rows, and the note says that this favours the model.

A model written by ``pkm-calib export`` has a sidecar (calib.compensate.sidecar) listing the
identified parameters its file cannot hold; when it lists any, the first line printed says
so: the model as it is predicts without them.
"""

from __future__ import annotations

import argparse
import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.compensate import missing_line
from calib.data import CALIBRATION, Dataset, read_dataset, select_set
from calib.fit import EXIT_OK, Registration, Side, bind_dataset, initial_registration, score_side
from common.atomic_files import json_text
from common.write_set import write_files
from twin.kinematics import forward_batch
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class AsIs:
    pose_ids: np.ndarray
    target_names: tuple[str, ...]
    side: Side
    registration: Registration | None
    note: str

    def as_dict(self) -> dict:
        return {
            "n_poses": len(self.pose_ids),
            "n_readings": self.side.position.n,
            "metric": "3D position error per reading |p_measured - p_model| (mm)",
            "as_is": self.side.as_dict(),
            "registration": None if self.registration is None else self.registration.as_dict(),
            "note": self.note,
        }

    def rows(self) -> list[dict]:
        return [
            {
                "pose_id": int(pid),
                "target": name,
                "error_mm": float(self.side.per_reading_m[p, t] * 1e3),
            }
            for p, pid in enumerate(self.pose_ids)
            for t, name in enumerate(self.target_names)
        ]


def score_as_is(mech: Mechanism, dataset: Dataset, set_name: str | None) -> tuple[AsIs, str]:
    """Score the rows of ``set_name`` (default: all) on ``mech`` as it is."""
    picked, selection = select_set(dataset, set_name, "verification")
    obs = bind_dataset(mech, picked)
    predicted = forward_batch(mech, obs.commands).targets
    measured, reg, note = obs.measured, None, "readings in the machine's base frame"
    if obs.frame == "tracker":
        sets = {str(s) for s in dataset.sets}
        if CALIBRATION in sets and set_name != CALIBRATION:
            cal, _ = select_set(dataset, CALIBRATION, "registration")
            cal_obs = bind_dataset(mech, cal)
            reg = initial_registration(
                cal_obs.measured, forward_batch(mech, cal_obs.commands).targets
            )
            note = (
                "tracker frame: registered by a rigid fit of the model to the "
                f"{cal.n_poses} poses of set '{CALIBRATION}'"
            )
        else:
            reg = initial_registration(obs.measured, predicted)
            note = (
                "tracker frame: no other calibration rows, so the registration is fitted to "
                "the scored readings themselves (it favours the model)"
            )
        measured = reg.to_base(obs.measured)
    side = score_side(mech, measured, predicted)
    return AsIs(np.asarray(picked.pose_ids), mech.target_names, side, reg, note), selection


def _csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=["pose_id", "target", "error_mm"], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def run(args: argparse.Namespace) -> int:
    lacks = missing_line(args.model)
    if lacks:
        print(lacks)
    mech = Mechanism.from_xml(args.model)
    dataset = read_dataset(args.data, expected_model=mech.name)
    scored, selection = score_as_is(mech, dataset, args.set)
    print(selection)
    print(scored.note)
    print(scored.side.line("model as it is"))
    if args.out:
        out = Path(args.out)
        content = {"model": str(args.model), "data": str(args.data), "set": args.set}
        if lacks:
            content["model_lacks"] = lacks
        body = json_text({**content, **scored.as_dict(), "selection": selection})
        csv_text = _csv_text(scored.rows())
        write_files({out: body, out.with_suffix(".csv"): csv_text}, make_parents=True)
        print(f"wrote {out} and {out.with_suffix('.csv')}")
    return EXIT_OK
