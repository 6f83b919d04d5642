"""Twin-made datasets with the characteristics of real measured data, for the CLI's tests.

What real machines hand the calibration, and what each case reproduces:

* ``few_pose_arm``: a 6R arm with one reflector, 30 poses (20 to calibrate, 10 held out), a
  tracker in its own frame metres away; joints that wind up under a payload (compliance) and
  a reflector nest placed to a few tenths of a millimetre: with one reflector, joint 6's zero
  and the reflector's offset in the plane normal to joint 6 are redundant.
* ``stewart_one_point``: a hexapod seen through one point (motion capture of one marker),
  108 poses (72 / 36), base joints off by millimetres, one leg's gain off by a few per cent
  (a revolution-to-mm factor): 54 parameters, a registration the base joints share, weak
  directions, a residual far above the declared accuracy.
* ``cobot``: a 6R arm with three reflectors, hundreds of poses, compliant joints under a
  payload, an honest tracker accuracy (0.02 mm): the geometric residual is 10-20 times the
  noise, the normal case on a real machine.

Each writes one Dataset CSV (calibration and test rows) beside the model and error model it
needs, and returns their paths. Only the twin (truth, effects, tracker) makes the readings;
what a test then runs is the command line a user types.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.data import write_dataset
from scenarios.twin_datasets import tracker_frame_dataset
from twin.effects import ActuatorGain, JointCompliance, ReflectorOffset
from twin.exceptions import ClosureError, WorkspaceError
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.single_pose import inverse
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses, uniform_commands, workspace_box

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"


@dataclass(frozen=True)
class Case:
    model: Path
    errors: Path
    data: Path
    sigma_mm: float  # the accuracy the sidecar declares
    truth: dict | None = None  # what a test may compare an answer with (never calib's input)


def _uniform(rng: np.random.Generator, params, translation_mm: float, rotation_deg: float):
    shown = np.where(
        params.is_angle,
        rng.uniform(-rotation_deg, rotation_deg, len(params)),
        rng.uniform(-translation_mm, translation_mm, len(params)),
    )
    return params.from_display(shown)


def _write(
    truth: Mechanism,
    commands: np.ndarray,
    n_cal: int,
    tracker: Tracker,
    effects: list,
    sigma_mm: float,
    path: Path,
    rng: np.random.Generator,
) -> Path:
    notes = "twin-made data with real characteristics (tests/real_like_cases.py)"
    ds = tracker_frame_dataset(truth, tracker, commands, n_cal, sigma_mm, rng, effects, notes)
    return write_dataset(ds, path)


def _arm_joints(mech: Mechanism, n: int, rng: np.random.Generator) -> np.ndarray:
    return uniform_commands(mech, n, 0.8, rng)


def arm_case(
    out_dir: Path,
    seed: int = 3,
    n_cal: int = 20,
    n_test: int = 10,
    three_reflectors: bool = False,
    sigma_mm: float = 0.02,
    payload_kg: float = 5.0,
    stiffness_Nm_per_rad: float = 5e4,
    noise: str = "gaussian 10 um",
    name: str = "arm",
    effects: bool = True,
) -> Case:
    """A 6R arm (one or three reflectors) in a tracker frame 4.5 m away, DH errors of a built
    arm, its reflector nest(s) off by up to 0.4 mm, joints compliant under a payload."""
    stem = "arm6r_3targets" if three_reflectors else "arm6r"
    model, errors = MODELS / f"{stem}.xml", MODELS / f"{stem}.params.toml"
    rng = np.random.default_rng(seed)
    nominal = Mechanism.from_xml(model)
    params = load_parameter_set(errors, nominal.model)
    truth = nominal.with_model(params.inject(nominal.model, _uniform(rng, params, 0.3, 0.03)))
    tracker = Tracker(
        position_m=(4.0, 2.0, 0.4),
        noise=TrackerNoise.from_spec(noise),
        rotation_rpy_rad=tuple(np.radians([0.4, -0.7, 100.0])),
    )
    physics = [
        JointCompliance(stiffness_Nm_per_rad=stiffness_Nm_per_rad, payload_kg=payload_kg),
        ReflectorOffset(magnitude_m=0.4e-3, seed=seed),
    ]
    commands = _arm_joints(nominal, n_cal + n_test, rng)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{name}.csv"
    data = _write(truth, commands, n_cal, tracker, physics if effects else [], sigma_mm, path, rng)
    return Case(model, errors, data, sigma_mm)


def few_pose_arm(out_dir: Path, seed: int = 3) -> Case:
    return arm_case(out_dir, seed=seed, name="few_pose_arm")


def cobot(out_dir: Path, seed: int = 5, n_cal: int = 300, n_test: int = 100) -> Case:
    return arm_case(
        out_dir, seed=seed, n_cal=n_cal, n_test=n_test, three_reflectors=True, name="cobot"
    )


def one_point_hexapod(out_dir: Path) -> tuple[Path, Path]:
    """The hexapod with one marker (target_1) instead of three: its MJCF and error model."""
    xml = (MODELS / "hexapod_rrrprr.xml").read_text()
    xml = re.sub(r'\s*<site name="target_[23]"[^>]*/>', "", xml)
    xml = xml.replace('model="hexapod_rrrprr"', 'model="stewart_one_point"')
    toml = (MODELS / "hexapod_rrrprr.params.toml").read_text()
    toml = toml.replace('model = "hexapod_rrrprr"', 'model = "stewart_one_point"')
    # a Stewart platform's error model: joint centres and leg lengths, not the offset arms
    blocks = toml.split("[[parameter]]")
    toml = "[[parameter]]".join(
        [blocks[0]] + [b for b in blocks[1:] if "_offset" not in b.split("\n")[1]]
    )
    out_dir.mkdir(parents=True, exist_ok=True)
    model, errors = out_dir / "stewart_one_point.xml", out_dir / "stewart_one_point.params.toml"
    model.write_text(xml)
    errors.write_text(toml)
    return model, errors


def stewart_one_point(
    out_dir: Path,
    seed: int = 7,
    n_cal: int = 72,
    n_test: int = 36,
    gain_percent: float = 3.0,
    base_mm: float = 3.0,
    sigma_mm: float = 0.05,
    leg: int = 1,
    reach: float | None = None,
    name: str = "stewart",
) -> Case:
    """A hexapod measured through one marker by motion capture: base joints off by up to
    ``base_mm``, the rest by 0.5 mm, leg ``leg + 1``'s gain ``gain_percent`` off, 0.2 mm
    capture noise; poses drawn over the workspace box, or (``reach``) over that fraction of
    it about its centre."""
    model, errors = one_point_hexapod(out_dir)
    rng = np.random.default_rng(seed)
    nominal = Mechanism.from_xml(model)
    params = load_parameter_set(errors, nominal.model)
    values = _uniform(rng, params, 0.5, 0.05)
    base = np.array([".base." in n for n in params.names])
    values[base] = params.from_display(rng.uniform(-base_mm, base_mm, len(params)))[base]
    truth = nominal.with_model(params.inject(nominal.model, values))
    tracker = Tracker(
        position_m=(1.5, -0.8, 1.2),
        noise=TrackerNoise.from_spec("gaussian 0.2 mm"),
        rotation_rpy_rad=tuple(np.radians([2.0, -1.0, 35.0])),
    )
    gains = np.zeros(nominal.n_actuators)
    gains[leg] = gain_percent * 1e4
    effects = [ActuatorGain(gains_ppm=tuple(gains))]
    if reach is None:
        _, commands = random_poses(nominal, n_cal + n_test, rng)
    else:
        commands = _near_home(nominal, n_cal + n_test, reach, rng)
    path = out_dir / f"{name}.csv"
    data = _write(truth, commands, n_cal, tracker, effects, sigma_mm, path, rng)
    return Case(model, errors, data, sigma_mm, {"gains_ppm": gains})


def _near_home(mech: Mechanism, n: int, reach: float, rng: np.random.Generator) -> np.ndarray:
    """Commands of ``n`` poses drawn uniformly over ``reach`` of the workspace box about its
    centre (unreachable draws skipped)."""
    lo, hi = workspace_box(mech)
    mid, half = (lo + hi) / 2, reach * (hi - lo) / 2
    commands: list[np.ndarray] = []
    for _ in range(50 * n):
        try:
            commands.append(inverse(mech, rng.uniform(mid - half, mid + half)).actuators)
        except (WorkspaceError, ClosureError):
            continue
        if len(commands) == n:
            return np.array(commands)
    raise WorkspaceError(f"only {len(commands)} of {n} poses near home were reachable")


def stewart_near_home(out_dir: Path, seed: int = 8) -> Case:
    """The Stewart platform of the motion-capture data: one marker, base joints up to 5 mm
    off, leg 1's gain -6 %, 0.2 mm capture noise, 72 calibration and 36 test poses over 70 %
    of the workspace box about its centre (home). Plain least squares creeps along its weak
    directions: at 50 and at 300 iterations it has not converged."""
    return stewart_one_point(
        out_dir,
        seed,
        gain_percent=-6.0,
        base_mm=5.0,
        sigma_mm=0.2,
        leg=0,
        reach=0.7,
        name="stewart_near_home",
    )


def hexapod_reflectors(
    out_dir: Path, seed: int = 4, n_cal: int = 80, n_test: int = 40, sigma_mm: float = 0.005
) -> Case:
    """The hexapod with its three reflectors off their nominal nests by 30-120 um (not in
    its error model), geometric errors of a built machine, a tracker at 5 um: geometry leaves
    about ten times the noise."""
    model, errors = MODELS / "hexapod_rrrprr.xml", MODELS / "hexapod_rrrprr.params.toml"
    rng = np.random.default_rng(seed)
    nominal = Mechanism.from_xml(model)
    params = load_parameter_set(errors, nominal.model)
    truth = nominal.with_model(params.inject(nominal.model, _uniform(rng, params, 0.2, 0.05)))
    direction = rng.normal(size=(nominal.n_targets, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    offsets = direction * rng.uniform(30e-6, 120e-6, (nominal.n_targets, 1))
    tracker = Tracker(
        position_m=(1.2, 0.9, 0.6),
        noise=TrackerNoise.from_spec(f"gaussian {sigma_mm} mm"),
        rotation_rpy_rad=tuple(np.radians([0.0, 0.0, 20.0])),
    )
    effects = [ReflectorOffset(offsets_m=tuple(offsets.reshape(-1)))]
    _, commands = random_poses(nominal, n_cal + n_test, rng)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "hexapod_reflectors.csv"
    data = _write(truth, commands, n_cal, tracker, effects, sigma_mm, path, rng)
    return Case(model, errors, data, sigma_mm, {"reflector_offsets_m": offsets})


def coupled_arm(
    out_dir: Path,
    seed: int = 11,
    n_cal: int = 400,
    n_inside: int = 100,
    n_outside: int = 10,
    region: float = 0.5,
) -> Case:
    """A 6R arm (three reflectors, tracker frame) whose joints deflect with the configuration
    (twin.effects.CrossCoupling: an effect no candidate of the diagnosis has), calibrated in
    a region (``region`` of each joint's range about its middle); the test rows: ``n_inside``
    poses in the region, then ``n_outside`` with every joint beyond it (a configuration the
    calibration never saw). ``truth['outside']``: the pose_ids of the latter."""
    from twin.effects import CrossCoupling

    model, errors = MODELS / "arm6r_3targets.xml", MODELS / "arm6r_3targets.params.toml"
    rng = np.random.default_rng(seed)
    nominal = Mechanism.from_xml(model)
    params = load_parameter_set(errors, nominal.model)
    truth = nominal.with_model(params.inject(nominal.model, _uniform(rng, params, 0.3, 0.03)))
    tracker = Tracker(
        position_m=(4.0, 2.0, 0.4),
        noise=TrackerNoise.from_spec("gaussian 10 um"),
        rotation_rpy_rad=tuple(np.radians([0.4, -0.7, 100.0])),
    )
    lo, hi = nominal.actuator_range.T
    mid, half = (lo + hi) / 2, (hi - lo) / 2
    inside = rng.uniform(mid - region * half, mid + region * half, (n_cal + n_inside, 6))
    # beyond the region in every joint: between 1.3 and 1.6 times its half-width from the middle
    sign = rng.choice([-1.0, 1.0], (n_outside, 6))
    outside = mid + sign * rng.uniform(1.3, 1.6, (n_outside, 6)) * region * half
    commands = np.vstack([inside, outside])
    out_dir.mkdir(parents=True, exist_ok=True)
    physics = [CrossCoupling(magnitude_rad=float(np.radians(0.08)), seed=seed)]
    data = _write(truth, commands, n_cal, tracker, physics, 0.02, out_dir / "coupled.csv", rng)
    ids = list(range(n_cal + n_inside + 1, n_cal + n_inside + n_outside + 1))
    return Case(model, errors, data, 0.02, {"outside": ids})
