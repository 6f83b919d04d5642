"""serial_arm, after verify: the loop closed through the user's commands.

    pkm-calib compensate --model M --errors E --result R.json --frame tracker
                               --poses desired.csv --out commands.csv
    pkm-calib export     --model M --errors E --result R.json --out M_calibrated.xml
                               --dh-out M_calibrated.mdh.csv
    pkm-calib verify     --model M_calibrated.xml --data D --set test --out V.json
    pkm-calib compensate --model M --errors E --result R.json
                               --commands program.csv --out corrected.csv

The desired tool positions are spread over the arm's workspace (the tool points of joint
commands drawn over a fraction of each range, kept where the nominal arm reaches them at its
home orientation with every joint a margin inside its range), given in the tracker's frame,
position only: where a user who measured a workpiece with the tracker wants the tool. The
truth twin then moves to the nominal commands (the nominal model, registered to the
calibration readings as verify's 'before' is) and to the compensated ones, and the true 3D
error of the tool point is taken in the tracker's frame. The exported model's kinematics is
compared with the identified model's at every command of the study, and the calibrated DH
table is turned back into a model and compared too.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from calib.compensate import kinematics_difference, solve_each
from calib.data import read_dataset, select_set
from calib.fit import bind_dataset, initial_registration, stats_mm
from scenarios.config import Scenario
from scenarios.studies.serial_arm.program import compensate_program
from twin.formats import build_xml, exact, read_dh_table
from twin.kinematics import forward, forward_batch
from twin.mechanism import Mechanism
from twin.rotations import rpy_from_matrix
from twin.tracker import Tracker

Cli = Callable[[list[str], Path], int]


def desired_positions(
    nominal: Mechanism, n: int, fraction: float, margin_rad: float, rng: np.random.Generator
) -> np.ndarray:
    """``n`` tool points (N, 3) (base frame) the nominal arm reaches at its home orientation
    with every joint ``margin_rad`` inside its range; drawn as the tool points of joint
    commands uniform over ``fraction`` of each range about its middle."""
    rpy0 = rpy_from_matrix(forward(nominal, nominal.home_qpos[nominal.actuator_qpos]).tool_rotation)
    lo, hi = nominal.actuator_range.T
    mid, half = (lo + hi) / 2, fraction * (hi - lo) / 2
    points: list[np.ndarray] = []
    for _ in range(50 * n):
        if len(points) == n:
            break
        p = forward(nominal, rng.uniform(mid - half, mid + half)).tool_position
        solved = solve_each(nominal, np.concatenate([p, rpy0])[None])
        c = solved.commands[0]
        if solved.reachable[0] and np.all((c > lo + margin_rad) & (c < hi - margin_rad)):
            points.append(p)
    if len(points) < n:
        raise ValueError(f"only {len(points)} of {n} desired positions reachable in {50 * n} draws")
    return np.array(points)


def _write_desired(path: Path, points_tracker: np.ndarray) -> None:
    rows = ["pose_id,x_mm,y_mm,z_mm"]
    rows += [
        f"{k + 1},{','.join(repr(float(v)) for v in p * 1e3)}" for k, p in enumerate(points_tracker)
    ]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def _read_commands(path: Path, mech: Mechanism) -> tuple[list[str], np.ndarray]:
    """pose ids and SI commands of a commands CSV written by compensate."""
    with path.open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    scale = np.where(mech.actuator_is_slide, 1e-3, np.radians(1.0))
    cmds = np.array([[float(r[f"cmd:{a}"]) for a in mech.actuator_names] for r in rows])
    return [r["pose_id"] for r in rows], cmds.reshape(-1, mech.n_actuators) * scale


def _true_errors(truth: Mechanism, tracker: Tracker, commands, desired_tracker) -> np.ndarray:
    """The truth twin's tool point at ``commands`` minus the desired one, in the frame of
    the tool (N, 3) (metres): its norm is the error in the tracker's frame."""
    sol = forward_batch(truth, commands)
    rot, t = tracker.base_from_tracker
    wanted = desired_tracker @ rot.T + t  # in the true base frame
    return np.einsum("nji,nj->ni", sol.tool_rotation, sol.tool_position - wanted)


def close_the_loop(
    scenario: Scenario,
    name: str,
    model_path: Path,
    errors_path: Path,
    data: Path,
    result_json: Path,
    truth: Mechanism,
    identified: Mechanism,
    tracker: Tracker,
    out_dir: Path,
    cli: Cli,
) -> dict[str, Any]:
    """compensate, re-measure on the truth twin, export and check; the summary entries."""
    nominal = Mechanism.from_xml(model_path)
    rng = np.random.default_rng([scenario.get("seed", int), 26])
    n = scenario.get("compensation.desired_poses", int)
    fraction = scenario.get("compensation.joint_fraction", float)
    margin = np.radians(scenario.get("compensation.stroke_margin_deg", float))
    desired_tracker = tracker.in_own_frame(desired_positions(nominal, n, fraction, margin, rng))
    desired_csv, commands_csv = out_dir / f"{name}_desired.csv", out_dir / f"{name}_commands.csv"
    _write_desired(desired_csv, desired_tracker)
    common = [
        "--model",
        str(model_path),
        "--errors",
        str(errors_path),
        "--result",
        str(result_json),
    ]
    code_comp = cli(
        [
            "compensate",
            *common,
            "--frame",
            "tracker",
            "--poses",
            str(desired_csv),
            "--out",
            str(commands_csv),
        ],
        out_dir / f"{name}_compensate.log",
    )
    ids, compensated = _read_commands(commands_csv, nominal)
    reached = np.array([int(i) - 1 for i in ids], dtype=int)
    # before: the nominal model, registered to the calibration readings (verify's 'before')
    cal = bind_dataset(nominal, select_set(read_dataset(data), "calibration", "registration")[0])
    reg0 = initial_registration(cal.measured, forward_batch(nominal, cal.commands).targets)
    rpy0 = rpy_from_matrix(forward(nominal, nominal.home_qpos[nominal.actuator_qpos]).tool_rotation)
    poses0 = np.hstack([reg0.to_base(desired_tracker), np.tile(rpy0, (n, 1))])
    plain = solve_each(nominal, poses0)
    both = reached[plain.reachable[reached]]
    before = _true_errors(truth, tracker, plain.commands[both], desired_tracker[both])
    after_vectors = _true_errors(truth, tracker, compensated, desired_tracker[reached])
    after = after_vectors[np.isin(reached, both)]
    constant = after_vectors.mean(axis=0)  # what stays with the tool: an offset it carries
    compensation = {
        "n_desired": n,
        "n_compared": len(both),
        "frame": "tracker",
        "orientation": "nominal (position-only rows)",
        "exit_code": code_comp,
        "n_unreachable": n - len(reached),
        "before": stats_mm(np.linalg.norm(before, axis=1)).as_dict(),
        "after": stats_mm(np.linalg.norm(after, axis=1)).as_dict(),
        "after_mean_in_tool_frame_mm": (constant * 1e3).tolist(),
        "after_spread_about_it_mm": stats_mm(
            np.linalg.norm(after_vectors - constant, axis=1)
        ).rms_mm,
        "metric": "true 3D error of the tool point at the desired position, tracker frame (mm)",
    }
    exported = out_dir / f"{name}_calibrated.xml"
    dh_out = out_dir / f"{name}_calibrated.mdh.csv"
    code_exp = cli(
        ["export", *common, "--out", str(exported), "--dh-out", str(dh_out)],
        out_dir / f"{name}_export.log",
    )
    model = Mechanism.from_xml(exported)
    commands = np.vstack([read_dataset(data).commands, compensated])
    check = kinematics_difference(identified, model, commands)
    table = read_dh_table(dh_out)
    from_table = Mechanism.from_xml_string(build_xml(table, nominal.name, number=exact))
    dh_check = kinematics_difference(identified, from_table, commands)
    verify_json = out_dir / f"{name}_calibrated_verify.json"
    code_ver = cli(
        [
            "verify",
            "--model",
            str(exported),
            "--data",
            str(data),
            "--set",
            "test",
            "--out",
            str(verify_json),
        ],
        out_dir / f"{name}_calibrated_verify.log",
    )
    as_is = json.loads(verify_json.read_text())["as_is"]
    export = {
        "exit_codes": {"export": code_exp, "verify_as_is": code_ver},
        "n_commands_checked": check.n_commands,
        "max_fk_diff_mm": check.max_position_m * 1e3,
        "max_tool_rotation_diff_deg": float(np.degrees(check.max_rotation_rad)),
        "dh_table_max_fk_diff_mm": dh_check.max_position_m * 1e3,
        "verify_as_is_test": {k: as_is[k] for k in ("n", "rms_mm", "mean_mm", "max_mm")},
    }
    program = None
    n_program = scenario.get("compensation.program_targets", int, None)
    if n_program:  # the robot's program, through compensate --commands (its own draws)
        program = compensate_program(
            name, model_path, errors_path, data, result_json, truth, tracker, (), out_dir, cli,
            n_program, fraction, np.random.default_rng([scenario.get("seed", int), 31]),
        )  # fmt: skip
    return {"compensation": compensation, "export": export, "program": program}
