"""Compensation with a diagnosed effect at the state the program runs at, re-measured on the twin.

A hexapod twin with thermal growth of its rods and backlash (0.005 mm tracker, 80 calibration
and 40 later poses): diagnose --out, identify --with, then compensate the 40 later targets as a
program (its order and time_s columns: the state it runs at) and run the corrected commands on
the same twin with the same effects at the same state. Without the effect the compensation
keeps the effect's error; with it the tool lands within the tracker's noise.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from calib.cli.commands import main
from scenarios.twin_datasets import measured_dataset, through_file
from twin.effects import Backlash, ThermalWarmup
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.kinematics import forward
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parents[1]
MODEL = str(ROOT / "models/hexapod_rrrprr.xml")
ERRORS = str(ROOT / "models/hexapod_rrrprr.params.toml")
SIGMA_M = 5e-6
N_CAL, N_TEST = 80, 40


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    out = tmp_path_factory.mktemp("state")
    nominal = Mechanism.from_xml(MODEL)
    params = load_parameter_set(ERRORS, nominal.model)
    values = load_values(str(ROOT / "scenarios/truth/hexapod_table2.toml"), params)
    truth = nominal.with_model(params.inject(nominal.model, values))
    effects = [
        ThermalWarmup(delta_K=8.0, tau_s=1200.0, seconds_per_pose=30.0, bodies="leg*_rod"),
        Backlash(play_m=8e-6),
    ]
    rng = np.random.default_rng(7)
    tracker = Tracker(position_m=(1.2, 0.0, 0.3), noise=TrackerNoise("gaussian", SIGMA_M, 0.0))
    poses, commands = random_poses(nominal, N_CAL + N_TEST, rng)
    order = np.arange(N_CAL + N_TEST)
    m = measure(truth, commands, tracker, rng, effects=effects, order=order)
    ds = measured_dataset(truth, commands, poses, "calibration", tracker, rng)
    sets = np.array(["calibration"] * N_CAL + ["test"] * N_TEST)
    ds = type(ds)(
        **{
            **ds.__dict__,
            "readings": m.readings,
            "order": order,
            "sets": sets,
            "time_s": 30.0 * order,
            "tracker": {**ds.tracker, "sigma_mm": SIGMA_M * 1e3},
        }
    )
    data = out / "d.csv"
    through_file(ds, data, nominal.name)
    files = ["--model", MODEL, "--errors", ERRORS]
    cal = [*files, "--data", str(data), "--set", "calibration"]
    assert main(["diagnose", *cal, "--test-set", "test", "--out", str(out / "d.json")]) == 0
    with_effect = ["--with", str(out / "d.json"), "--out", str(out / "r.json")]
    assert main(["identify", *cal, *with_effect]) == 0
    assert main(["identify", *cal, "--out", str(out / "g.json")]) == 0
    later = commands[N_CAL:]
    head = ["pose_id", *(f"cmd:{a}" for a in nominal.actuator_names), "order", "time_s"]
    rows = [
        [f"p{o}", *(f"{v * 1e3:.9f}" for v in c), str(o), f"{30.0 * o:g}"]
        for c, o in zip(later, order[N_CAL:], strict=True)
    ]
    (out / "prog.csv").write_text("\n".join(",".join(r) for r in [head, *rows]) + "\n")
    return {
        "out": out,
        "files": files,
        "nominal": nominal,
        "truth": truth,
        "effects": effects,
        "later": later,
        "order": order[N_CAL:],
        "tracker": tracker,
    }


def _compensated(t, result: str, extra: list[str], name: str) -> np.ndarray:
    out = t["out"] / name
    code = main(
        ["compensate", *t["files"], "--result", str(t["out"] / result), "--out", str(out), *extra]
    )
    assert code in (0, 5)  # 5: a target whose corrected command leaves a stroke, named
    acts = t["nominal"].actuator_names
    with open(out, newline="") as f:
        got = {r["pose_id"]: [float(r[f"cmd:{a}"]) * 1e-3 for a in acts] for r in csv.DictReader(f)}
    return np.array([got.get(f"p{o}", [np.nan] * len(acts)) for o in t["order"]])


def _tool_error_mm(t, commands: np.ndarray) -> np.ndarray:
    """The twin's tool point at the commands, with the effects at the program's state, less
    where the nominal model puts it at the program's own commands."""
    ok = np.all(np.isfinite(commands), axis=1)
    rng = np.random.default_rng(11)
    m = measure(
        t["truth"], commands[ok], t["tracker"], rng, effects=t["effects"], order=t["order"][ok]
    )
    want = np.array([forward(t["nominal"], c).tool_position for c in t["later"][ok]])
    return np.linalg.norm(m.true_position - want, axis=1) * 1e3


def test_compensation_with_the_effect_lands_at_the_noise(twin, capsys):
    prog = ["--commands", str(twin["out"] / "prog.csv")]
    geo = _tool_error_mm(twin, _compensated(twin, "g.json", prog, "comp_g.csv"))
    capsys.readouterr()
    with_effect = _tool_error_mm(twin, _compensated(twin, "r.json", prog, "comp_r.csv"))
    said = capsys.readouterr().out
    assert "approach directions: derived from the program's sequence (its order column" in said
    assert "time_s: the program's column (2400 to 3570)" in said
    assert len(with_effect) >= N_TEST - 2  # at most a target or two past a stroke
    noise_3d = SIGMA_M * 1e3 * np.sqrt(3)  # one reading's 3D noise: what the data resolve
    rms = float(np.sqrt(np.mean(with_effect**2)))
    assert rms <= noise_3d
    # the geometry alone leaves the growth and the play: measurably more than with the effect
    assert rms <= 0.5 * float(np.sqrt(np.mean(geo**2)))


def test_compensation_refuses_a_missing_state_by_name(twin, capsys):
    bare = twin["out"] / "bare.csv"
    lines = (twin["out"] / "prog.csv").read_text().splitlines()
    bare.write_text("\n".join(",".join(x.split(",")[:7]) for x in lines) + "\n")
    args = ["--commands", str(bare)]
    out = twin["out"] / "x.csv"
    res = ["--result", str(twin["out"] / "r.json"), "--out", str(out)]
    code = main(["compensate", *twin["files"], *res, *args])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert "thermal_growth (leg1.growth" in err and "--time-s S or a time_s column" in err
    # one time for every target is a state too, and said
    cmds = _compensated(twin, "r.json", [*args, "--time-s", "3000"], "comp_t.csv")
    assert "time_s: 3000 for every target (--time-s)" in capsys.readouterr().out
    assert np.isfinite(cmds).any()
    # a column and the option both: ambiguous, refused
    both = ["--commands", str(twin["out"] / "prog.csv"), "--time-s", "3000"]
    res = ["--result", str(twin["out"] / "r.json"), "--out", str(out)]
    code = main(["compensate", *twin["files"], *res, *both])
    assert code == 2 and "both the program's column and --time-s" in capsys.readouterr().err
