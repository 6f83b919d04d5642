"""What a campaign of N readings costs: identify and diagnose as a user runs them (the command
line, in a fresh process each), wall time and peak memory, on twin data of 1k, 10k and 100k
readings of a 6R arm (one reflector) and of the hexapod (three reflectors), and the ratios
10k/1k and 100k/10k, so that growth is read in one run.

The readings are made by the twin (a uniform truth, a 0.01 mm tracker in the base frame, 90 %
calibration and 10 % test rows) and written as a Dataset; each command runs in its own child
process, which reports its own peak resident memory (bench.child_peak: not the benchmark
process's, which Linux would carry into it).
"""

from __future__ import annotations

import itertools
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from calib.data import write_dataset
from scenarios.config import REPO_ROOT
from scenarios.truth_draw import TruthSpec, draw_truth
from scenarios.twin_datasets import measured_dataset
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_commands

READINGS = (1_000, 10_000, 100_000)
MACHINES = {  # name: (MJCF, error model)
    "arm": ("models/arm6r.xml", "models/arm6r.params.toml"),
    "hexapod": ("models/hexapod_rrrprr.xml", "models/hexapod_rrrprr.params.toml"),
}


def campaign(machine: str, n_readings: int, folder: Path, seed: int = 0) -> Path:
    """A twin-made Dataset of about ``n_readings`` readings of ``machine`` in ``folder``."""
    xml, errors = MACHINES[machine]
    nominal = Mechanism.from_xml(REPO_ROOT / xml)
    params = load_parameter_set(REPO_ROOT / errors, nominal.model)
    rng = np.random.default_rng(seed)
    spec = TruthSpec("uniform", 0.3, 0.03, 0.0, 0.05)
    truth = nominal.with_model(params.inject(nominal.model, draw_truth(params, spec, rng)))
    n_poses = max(n_readings // len(nominal.target_names), 10)
    cmds = random_commands(nominal, n_poses, 0.8, rng)  # an arm: 80 % of each range
    tracker = Tracker(noise=TrackerNoise("gaussian", 1e-5, 0.0))
    ds = measured_dataset(truth, cmds, np.zeros((n_poses, 6)), "calibration", tracker, rng)
    n_cal = round(0.9 * n_poses)
    sets = np.array(["calibration"] * n_cal + ["test"] * (n_poses - n_cal))
    declared = {**(ds.tracker or {}), "sigma_mm": 0.01}
    ds = replace(ds, sets=sets, commanded_poses=None, tracker=declared)
    return write_dataset(ds, folder / f"{machine}_{n_readings}.csv")


def run_measured(args: list[str], module: str = "calib") -> dict:
    """Run ``python -m MODULE ARGS`` (``module`` "import:NAME": only import NAME) in a child
    process: wall time, its own peak memory (bench.child_peak), exit code."""
    with tempfile.TemporaryDirectory() as tmp:
        peak_file = Path(tmp) / "peak_kb"
        start = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "bench.child_peak", str(peak_file), module, *args],
            cwd=REPO_ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        _, err_bytes = proc.communicate()
        wall = time.perf_counter() - start
        peak_kb = float(peak_file.read_text()) if peak_file.is_file() else float("nan")
    err = err_bytes.decode(errors="replace")
    return {
        "wall_s": wall,
        "peak_mb": peak_kb / 1024.0,
        "exit_code": proc.returncode,
        **({"stderr": err[-500:]} if proc.returncode != 0 else {}),
    }


def scaling(readings: tuple[int, ...] = READINGS, diagnose_max: int | None = None) -> dict:
    """identify and diagnose per machine and size; ``diagnose_max``: the largest campaign
    diagnosed (None: all)."""
    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for machine, (xml, errors) in MACHINES.items():
            rows: dict = {}
            for n in readings:
                data = campaign(machine, n, folder)
                model = ["--model", str(REPO_ROOT / xml), "--errors", str(REPO_ROOT / errors)]
                common = [*model, "--data", str(data), "--set", "calibration"]
                row = {"identify": run_measured(["identify", *common])}
                if diagnose_max is None or n <= diagnose_max:
                    row["diagnose"] = run_measured(["diagnose", *common, "--test-set", "test"])
                rows[str(n)] = row
                print(f"scaling {machine} {n} readings: {_line(row)}", flush=True)
            out[machine] = {
                "by_readings": rows,
                "ratios": _ratios(rows, readings),
                "diagnose_over_identify": {
                    n: row["diagnose"]["wall_s"] / row["identify"]["wall_s"]
                    for n, row in rows.items()
                    if "diagnose" in row
                },
            }
    return out


def _line(row: dict) -> str:
    return "; ".join(
        f"{cmd} {r['wall_s']:.2f} s, {r['peak_mb']:.0f} MB (exit {r['exit_code']})"
        for cmd, r in row.items()
    )


def _ratios(rows: dict, readings: tuple[int, ...]) -> dict:
    """time and memory of each size over the previous one (10k/1k, 100k/10k)."""
    out: dict = {}
    for small, large in itertools.pairwise(readings):
        for cmd in ("identify", "diagnose"):
            a, b = rows[str(small)].get(cmd), rows[str(large)].get(cmd)
            if a and b:
                key = f"{cmd}_{large // 1000}k_over_{small // 1000}k"
                out[key] = {
                    "time": b["wall_s"] / a["wall_s"],
                    "memory": b["peak_mb"] / a["peak_mb"],
                }
    return out
