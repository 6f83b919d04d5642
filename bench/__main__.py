"""Speed benchmark (``make bench``): results/bench.json and results/bench.md.

* forward kinematics of the hexapod, the polisher and the serial arm: single pose and batched
  (twin.kinematics.batch.forward_batch, 10,000 poses, best of 5, on the compiled kernels and
  on the numpy path alternately), poses per second (bench.fk);
* identification on each machine (bench.machines): ours (calib.fit.identification, robust by
default and
  plain least squares) against scipy.optimize.least_squares with a finite-difference Jacobian
  on a fresh model over the same free parameters with tolerances as tight as ours, best of N,
  both answers compared (bench.identification);
* what a campaign costs (bench.scaling): identify and diagnose from the command line on twin
  data of 1k, 10k and 100k readings of the 6R arm and the hexapod, wall time and peak memory
  each, with the ratios 10k/1k and 100k/10k (diagnose up to 10k unless BENCH_ALL=1);
* every scenario run whole into a temporary results root (bench.scenario_times);
  optimal_poses only with BENCH_ALL=1.
* how soon the command line answers (bench.command_line): identify on a 20-pose arm against
  the bare import of the command line.
Targets (bench.targets, on 2 cores): identification >= 15 x scipy FD and faster than scipy
with our analytic Jacobian on every machine, >= 50,000 batched FK poses/s on the hexapod; a
campaign's time and memory (identify within 15 x from 1k to 10k readings, under 1.5 GB at 10k
and 4 GB at 100k; diagnose under 2 GB and 6 x identify's time at 10k); identify on a 20-pose
arm within 2 x the bare import; optimal_poses <= 90 s, liu_vs_ols <= 3 s without figures and
<= 6 s with them, hexapod_paper <= 30 s. ``meets_targets`` says which are met; a target whose
number was not measured is left out of it. The top-level keys of earlier versions are kept
(the hexapod's numbers).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from bench.command_line import command_line_start
from bench.fk import fk_rates
from bench.identification import SCIPY_OPTIONS, compare
from bench.machines import MACHINES
from bench.report import bench_markdown
from bench.scaling import scaling
from bench.scenario_times import scenario_times
from bench.targets import TARGETS, meets, value_at
from common.atomic_files import json_text
from common.write_set import write_files
from scenarios.config import REPO_ROOT

REPEATS = {"hexapod": 3, "polisher": 2, "arm": 3}  # best of N, for ours and the baseline
LEGACY = {  # top-level key of earlier versions -> the hexapod's key
    "fk_single_ms": "fk_single_ms",
    "fk_batch_poses_per_s": "fk_batch_poses_per_s",
    "fk_batch_speedup_vs_single": "fk_batch_speedup_vs_single",
    "identify_256_ours_s": "identify_ours_s",
    "identify_256_scipy_fd_s": "identify_scipy_fd_s",
    "identify_speedup_vs_scipy_fd": "identify_speedup_vs_scipy_fd",
    "identify_ours_vs_scipy_max_abs_diff_mm": "identify_ours_vs_scipy_max_abs_diff_mm",
}


def main() -> None:
    out: dict = {"cpu_count": os.cpu_count(), "scipy_options": SCIPY_OPTIONS, "machines": {}}
    for name, build in MACHINES.items():
        m = build()
        row = fk_rates(m.truth, m.obs.commands)
        print(
            f"{name}: FK single {row['fk_single_ms']:.3f} ms/pose, batched "
            f"{row['fk_batch_poses_per_s']:.0f} poses/s ({row['fk_batch_speedup_vs_single']:.1f}x; "
            f"numpy path {row['fk_batch_numpy_poses_per_s']:.0f} poses/s)",
            flush=True,
        )
        row.update(compare(m, REPEATS[name]))
        print(
            f"{name}: identify {row['n_identified']} of {row['n_parameters']} from "
            f"{row['n_poses']} poses: ours {row['identify_ours_s']:.2f} s (plain "
            f"{row['identify_ours_plain_s']:.2f} s), scipy FD {row['identify_scipy_fd_s']:.2f} s "
            f"({row['identify_speedup_vs_scipy_fd']:.1f}x); answers differ by "
            f"{row['identify_ours_vs_scipy_max_abs_diff_mm']:.2g} mm, "
            f"{row['identify_ours_vs_scipy_max_abs_diff_deg']:.2g} deg",
            flush=True,
        )
        out["machines"][name] = row
    hexapod = out["machines"]["hexapod"]
    for key, source in LEGACY.items():
        out[key] = hexapod[source]
    every = os.environ.get("BENCH_ALL") == "1"
    out["scaling"] = scaling(diagnose_max=None if every else 10_000)
    out["command_line"] = start = command_line_start()
    print(
        f"command line: identify on a {start['poses']}-pose arm {start['identify_s']:.2f} s, "
        f"the bare import {start['import_s']:.2f} s ({start['identify_over_import']:.2f}x)",
        flush=True,
    )
    times, skipped, errors = scenario_times()
    out.update(times)
    out["scenarios_skipped"] = skipped
    out["scenario_errors"] = errors
    out["targets"] = {k: t for k, (_, t, _) in TARGETS.items()}
    out["meets_targets"] = {}
    for key, (op, target, _) in TARGETS.items():
        value = value_at(out, key)
        if value is not None:
            out["meets_targets"][key] = meets(op, value, target)
    out["not_measured"] = {
        "make test": "<= 3 min on 2 cores: a test-suite target, not timed by the benchmark"
    }
    results = Path(REPO_ROOT / "results")
    path = results / "bench.json"
    try:  # both files, or neither
        write_files({path: json_text(out), results / "bench.md": bench_markdown(out)}, True)
    except OSError as exc:  # a full disk, a read-only results folder
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    print(f"wrote {path} and {results / 'bench.md'}")


if __name__ == "__main__":
    main()
