"""A robot's program through the calibration, as a user runs it, re-measured on the twin.

    pkm-calib compensate --model M --errors E --result R.json
                               --commands program.csv --out corrected.csv

The program is ``n`` joint targets drawn over a fraction of each joint's range. Its intent is
where the nominal model puts the tool point at the program's commands, as the tracker sees
it through the nominal model's registration on the calibration readings (the frame verify's
"before" uses). The truth twin, with its physical effects, is then moved to the program's
commands ("before") and to the corrected ones ("after"): the true 3D error of the tool point
against the intent in the tracker's frame, its constant part in the tool's frame (what no
reflector reading sees: an offset of the tool point along the flange axis) and the spread
about it, and how far the corrected joints moved from the program's.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from calib.data import read_dataset, select_set
from calib.fit import bind_dataset, initial_registration, stats_mm
from twin.kinematics import forward_batch
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import uniform_commands

Cli = Callable[[list[str], Path], int]


def _write_program(path: Path, mech: Mechanism, commands: np.ndarray) -> None:
    scale = np.where(mech.actuator_is_slide, 1e3, np.degrees(1.0))
    with path.open("w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["pose_id", *(f"cmd:{a}" for a in mech.actuator_names)])
        for k, c in enumerate(commands * scale):
            w.writerow([k + 1, *(repr(float(v)) for v in c)])


def _read_corrected(path: Path, mech: Mechanism) -> tuple[np.ndarray, np.ndarray]:
    """(row index in the program, SI commands) of the targets compensate wrote."""
    with path.open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    scale = np.where(mech.actuator_is_slide, 1e-3, np.radians(1.0))
    cmds = np.array([[float(r[f"cmd:{a}"]) for a in mech.actuator_names] for r in rows])
    index = np.array([int(r["pose_id"]) - 1 for r in rows], dtype=int)
    return index, cmds.reshape(-1, mech.n_actuators) * scale


def compensate_program(
    name: str,
    model_path: Path,
    errors_path: Path,
    data: Path,
    result_json: Path,
    truth: Mechanism,
    tracker: Tracker,
    effects: Sequence,
    out_dir: Path,
    cli: Cli,
    n: int,
    fraction: float,
    rng: np.random.Generator,
) -> dict[str, Any]:
    """compensate --commands of an ``n``-target program, re-measured on the truth twin."""
    nominal = Mechanism.from_xml(model_path)
    program = uniform_commands(nominal, n, fraction, rng)
    program_csv, corrected_csv = out_dir / f"{name}_program.csv", out_dir / f"{name}_corrected.csv"
    _write_program(program_csv, nominal, program)
    files = ["--model", str(model_path), "--errors", str(errors_path)]
    code = cli(
        [
            "compensate",
            *files,
            "--result",
            str(result_json),
            "--commands",
            str(program_csv),
            "--out",
            str(corrected_csv),
        ],
        out_dir / f"{name}_compensate_program.log",
    )
    index, corrected = _read_corrected(corrected_csv, nominal)
    cal = bind_dataset(nominal, select_set(read_dataset(data), "calibration", "registration")[0])
    reg0 = initial_registration(cal.measured, forward_batch(nominal, cal.commands).targets)
    intent = reg0.to_tracker(forward_batch(nominal, program[index]).tool_position)  # (N, 3)
    exact = replace(tracker, noise=TrackerNoise.none())

    def errors(commands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The true tool point's error (N, 3) in the tracker's frame, and in the tool's."""
        m = measure(truth, commands, exact, rng, effects=effects)
        e = tracker.in_own_frame(m.true_position) - intent
        rot, _ = tracker.base_from_tracker
        return e, np.einsum("nji,nj->ni", m.true_rotation, e @ rot.T)

    before, _ = errors(program[index])
    after, in_tool = errors(corrected)
    constant = in_tool.mean(axis=0)
    scale = np.where(nominal.actuator_is_slide, 1e3, np.degrees(1.0))
    moved = np.abs(corrected - program[index]) * scale
    return {
        "n_targets": n,
        "n_written": len(index),
        "exit_code": code,
        "before": stats_mm(np.linalg.norm(before, axis=1)).as_dict(),
        "after": stats_mm(np.linalg.norm(after, axis=1)).as_dict(),
        "after_mean_in_tool_frame_mm": (constant * 1e3).tolist(),
        "after_spread_about_it_mm": stats_mm(np.linalg.norm(in_tool - constant, axis=1)).rms_mm,
        "max_joint_change": {
            a: float(v) for a, v in zip(nominal.actuator_names, moved.max(axis=0), strict=True)
        },
        "metric": "true 3D error of the tool point against the nominal intent, tracker frame (mm)",
    }
