"""ISO 9283 pose accuracy (AP) and repeatability (RP) before and after a calibration.

For each machine (the hexapod, the 6R arm; three reflectors each) the truth twin carries a
seeded draw of geometric errors. One dataset file holds a calibration set (random poses) and
the set 'iso': the standard's five poses on a cube about the tool pose of the commands at a
fraction of every stroke (``at_stroke``), at its orientation. P1 is the centre; P2-P5 lie on
the diagonal plane through the cube's edges C1-C2 (along x at y = z = -edge/2) and C7-C8
(along x at y = z = +edge/2), 10 % of the plane's diagonal from its corners. The nominal
model's inverse kinematics commands them (what the controller does), each reached
``plan.cycles`` times in cycles P1..P5. The machine's own repeatability is a gaussian pose
noise; the tracker adds its own. Then, in process, exactly as a user:

    pkm-calib identify --model M --errors E --data D --set calibration --out R.json
    pkm-calib verify   --model M --errors E --data D --result R.json --set iso \\
                             --iso9283 --out iso.json

The numbers come from the files those commands write.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from calib.data import Dataset, write_dataset
from scenarios.config import Scenario, ScenarioError
from scenarios.progress import Progress
from scenarios.recording.recorder import Recorder
from scenarios.studies.serial_arm.study import _cli, _tracker
from scenarios.truth_draw import TruthSpec, draw_truth
from scenarios.twin_datasets import machine_fields
from twin.formats import load_parameter_set
from twin.kinematics import forward_batch, inverse
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.rotations import rpy_from_matrix
from twin.tracker import PoseNoise
from twin.workspace import random_poses, uniform_commands

PLANE_CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1]], dtype=float)


def iso_cube_poses(centre: np.ndarray, rpy: np.ndarray, edge_m: float) -> np.ndarray:
    """The five poses (5, 6) [x y z rx ry rz] of the standard on a cube of ``edge_m`` about
    ``centre``: P1 the centre, P2-P5 at 10 % of the plane's diagonal from its corners (a
    fifth of the way from each corner to the centre, which is the diagonal's middle)."""
    corners = centre + PLANE_CORNERS * edge_m / 2
    points = np.vstack([centre, corners + 0.2 * (centre - corners)])
    return np.hstack([points, np.tile(rpy, (5, 1))])


def _calibration_commands(mech: Mechanism, n: int, fraction: float, rng) -> np.ndarray:
    if mech.workspace_min is not None:  # a parallel machine: poses in its declared box
        return random_poses(mech, n, rng)[1]
    return uniform_commands(mech, n, fraction, rng)


def _iso_commands(
    mech: Mechanism, edge_m: float, at: float, name: str
) -> tuple[np.ndarray, np.ndarray]:
    """The nominal commands of the five cube poses about the tool pose of the commands at
    the fraction ``at`` of every stroke (away from a wrist singularity for an arm)."""
    lo, hi = mech.actuator_range.T
    mid = forward_batch(mech, (lo + at * (hi - lo))[None])
    centre = mid.tool_position[0]
    rpy = rpy_from_matrix(mid.tool_rotation[0])
    poses = iso_cube_poses(centre, rpy, edge_m)
    try:
        cmds = np.array([inverse(mech, p, start=mid.qpos[0]).actuators for p in poses])
    except Exception as exc:  # the cube must lie in the workspace: say which machine
        raise ScenarioError(f"{name}: an ISO cube pose is not reachable: {exc}") from None
    return cmds, poses


def _machine(
    scenario: Scenario,
    name: str,
    keys: tuple[str, str, str, str],
    out_dir: Path,
    rng: np.random.Generator,
    progress: Progress,
) -> dict[str, Any]:
    model_key, errors_key, edge_key, at_key = keys
    model = scenario.resolve(scenario.get(model_key, str), model_key)
    errors = scenario.resolve(scenario.get(errors_key, str), errors_key)
    nominal = Mechanism.from_xml(model)
    params = load_parameter_set(errors, nominal.model)
    truth_values = draw_truth(params, TruthSpec.from_scenario(scenario), rng)
    truth = nominal.with_model(params.inject(nominal.model, truth_values))
    n_cal = scenario.get("plan.calibration_poses", int)
    cycles = scenario.get("plan.cycles", int)
    fraction = scenario.get("arm.joint_fraction", float)
    cal = _calibration_commands(nominal, n_cal, fraction, rng)
    edge_m, at = scenario.get(edge_key, float) * 1e-3, scenario.get(at_key, float)
    iso, poses = _iso_commands(nominal, edge_m, at, name)
    commands = np.vstack([cal, np.tile(iso, (cycles, 1))])  # cycles P1..P5, P1..P5, ...
    tracker = _tracker(scenario)
    repeat = PoseNoise(
        "gaussian",
        scenario.get("repeatability.position_mm", float) * 1e-3,
        float(np.radians(scenario.get("repeatability.rotation_deg", float))),
    )
    m = measure(truth, commands, tracker, rng, pose_noise=repeat)
    n = len(commands)
    sigma_mm = scenario.get("tracker.sigma_mm", float)
    ds = Dataset(
        **machine_fields(nominal),
        frame="tracker",
        pose_ids=np.arange(1, n + 1),
        sets=np.array(["calibration"] * n_cal + ["iso"] * (n - n_cal)),
        commands=commands,
        readings=tracker.in_own_frame(m.readings),
        order=np.arange(n),
        tracker={"noise": tracker.noise.describe(), "sigma_mm": sigma_mm},
        notes=f"twin: {name}, ISO 9283 cube poses in set 'iso'",
    )
    (out_dir / "datasets").mkdir(parents=True, exist_ok=True)
    data = write_dataset(ds, out_dir / "datasets" / f"{name}.csv")
    result, report = out_dir / f"{name}_result.json", out_dir / f"{name}_iso9283.json"
    common = ["--model", str(model), "--errors", str(errors), "--data", str(data)]
    progress.step(f"{name}: identify --set calibration, verify --set iso --iso9283")
    code_id = _cli(
        ["identify", *common, "--set", "calibration", "--out", str(result)],
        out_dir / f"{name}_identify.log",
    )
    if not result.is_file():
        raise ScenarioError(f"{name}: identify exited {code_id} without a result")
    iso_args = ["--set", "iso", "--iso9283", "--out", str(report)]
    code_ver = _cli(
        ["verify", *common, "--result", str(result), *iso_args],
        out_dir / f"{name}_iso9283.log",
    )
    if not report.is_file():
        raise ScenarioError(f"{name}: verify --iso9283 exited {code_ver} without a report")
    iso_report = json.loads(report.read_text())
    return {
        "model": str(model),
        "n_calibration_poses": n_cal,
        "cycles": cycles,
        "cube_edge_mm": scenario.get(edge_key, float),
        "cube_poses_mm_deg": np.hstack([poses[:, :3] * 1e3, np.degrees(poses[:, 3:])]).tolist(),
        "calibration_residual": json.loads(result.read_text())["residual"],
        "exit_codes": {"identify": code_id, "verify": code_ver},
        "iso9283": iso_report,
    }


def run(
    scenario: Scenario, out_dir: Path, progress: Progress, recorder: Recorder
) -> dict[str, Any]:
    t0 = time.perf_counter()
    rng = np.random.default_rng(scenario.get("seed", int))
    machines = {
        "hexapod": _machine(
            scenario,
            "hexapod",
            ("model", "error_model", "cube.edge_mm", "cube.at_stroke"),
            out_dir,
            rng,
            progress,
        ),
        "arm": _machine(
            scenario,
            "arm",
            ("arm.model", "arm.error_model", "arm.edge_mm", "arm.at_stroke"),
            out_dir,
            rng,
            progress,
        ),
    }
    summary = {
        "study": "iso9283",
        "repeatability": {
            "position_mm": scenario.get("repeatability.position_mm", float),
            "rotation_deg": scenario.get("repeatability.rotation_deg", float),
        },
        "tracker_noise": scenario.get("tracker.noise", str),
        "machines": machines,
        "runtime_s": time.perf_counter() - t0,
    }
    recorder.log_report("iso9283", summary)
    return summary
