"""The benchmark's targets: read at their dotted keys, met or not by the number, and the
report says which (a slower run is 'not met', a number the run did not take is 'not
measured')."""

from __future__ import annotations

import numpy as np

from bench.report import bench_markdown
from bench.scaling import run_measured
from bench.targets import TARGETS, meets, value_at


def _out(diagnose_s: float) -> dict:
    rows = {
        "10000": {
            "identify": {"wall_s": 2.0, "peak_mb": 300.0, "exit_code": 0},
            "diagnose": {"wall_s": diagnose_s, "peak_mb": 700.0, "exit_code": 0},
        }
    }
    block = {"by_readings": rows, "ratios": {}, "diagnose_over_identify": {"10000": diagnose_s / 2}}
    machines = {"arm": {"n_poses": 256, "poses": "256 joint commands"}}
    out = {"cpu_count": 2, "scipy_options": {}, "machines": machines, "scaling": {"arm": block}}
    out["targets"] = {k: t for k, (_, t, _) in TARGETS.items()}
    out["meets_targets"] = {
        k: meets(op, value_at(out, k), t)
        for k, (op, t, _) in TARGETS.items()
        if value_at(out, k) is not None
    }
    return out


def test_targets_read_at_their_keys_and_can_fail():
    key = "scaling.arm.diagnose_over_identify.10000"
    assert TARGETS[key][:2] == ("<=", 6)
    fast, slow = _out(10.0), _out(30.0)
    assert value_at(fast, key) == 5.0 and value_at(slow, key) == 15.0
    assert fast["meets_targets"][key] is True and slow["meets_targets"][key] is False
    peak = "scaling.arm.by_readings.10000.diagnose.peak_mb"
    assert value_at(slow, peak) == 700.0 and slow["meets_targets"][peak] is True
    assert value_at(slow, "scaling.hexapod.by_readings.10000.diagnose.peak_mb") is None
    assert meets(">=", 15.0, 15) and not meets(">=", 14.9, 15) and not meets("<=", 2.1, 2)


def test_report_says_met_not_met_and_not_measured():
    md = bench_markdown(_out(30.0))
    line = next(x for x in md.splitlines() if "`scaling.arm.diagnose_over_identify.10000`" in x)
    assert "| 15 | <= 6 | **not met** |" in line
    line = next(x for x in md.splitlines() if "`command_line.identify_over_import`" in x)
    assert line.endswith("| - | <= 2 | not measured |")
    assert "| arm | diagnose over identify, 10000 readings | 15 | - |" in md


def test_a_child_reports_its_own_peak_memory_not_the_benchmarks():
    """Linux carries a process's resident high-water mark across exec: a command started by a
    large benchmark process must still report its own peak (bench.child_peak)."""
    held = np.ones(40_000_000)  # 320 MB resident in this process
    small = run_measured([], "import:json")
    assert held.sum() == 40_000_000
    assert small["exit_code"] == 0 and 1.0 < small["peak_mb"] < 100.0
    failed = run_measured(["identify"])  # the command's own exit code and message come back
    assert failed["exit_code"] == 2 and "required: --model" in failed["stderr"]
