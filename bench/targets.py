"""What ``make bench`` holds its numbers to: key in bench.json -> (comparison, target, what it
is). A target whose number the run did not measure is left out of ``meets_targets``."""

from __future__ import annotations

_SPEED = "identify's speedup vs scipy least_squares"
_SCALE = "a campaign of"

TARGETS: dict[str, tuple[str, float, str]] = {
    "machines.hexapod.fk_batch_poses_per_s": (">=", 50000, "batched FK poses/s, hexapod"),
    **{
        f"machines.{m}.identify_speedup_vs_scipy_fd": (">=", 15, f"{_SPEED} (FD Jacobian), {m}")
        for m in ("hexapod", "polisher", "arm")
    },
    **{
        f"machines.{m}.identify_speedup_vs_scipy_analytic": (
            ">=",
            1,
            f"{_SPEED} (our analytic Jacobian), {m}",
        )
        for m in ("hexapod", "polisher", "arm")
    },
    "command_line.identify_over_import": (
        "<=",
        2,
        "identify on a 20-pose arm over the bare import of the command line",
    ),
    **{
        key: target
        for m in ("arm", "hexapod")
        for key, target in {
            f"scaling.{m}.ratios.identify_10k_over_1k.time": (
                "<=",
                15,
                f"identify's time, 10k over 1k readings, {m}",
            ),
            f"scaling.{m}.by_readings.100000.identify.peak_mb": (
                "<=",
                4096,
                f"identify's peak MB, {_SCALE} 100k readings, {m}",
            ),
            f"scaling.{m}.by_readings.10000.identify.peak_mb": (
                "<=",
                1536,
                f"identify's peak MB, {_SCALE} 10k readings, {m}",
            ),
            f"scaling.{m}.by_readings.10000.diagnose.peak_mb": (
                "<=",
                2048,
                f"diagnose's peak MB, {_SCALE} 10k readings, {m}",
            ),
            f"scaling.{m}.diagnose_over_identify.10000": (
                "<=",
                6,
                f"diagnose's time over identify's, {_SCALE} 10k readings, {m}",
            ),
        }.items()
    },
    "scenario_optimal_poses_s": ("<=", 90, "optimal_poses (s)"),
    "scenario_liu_vs_ols_no_figures_s": ("<=", 3, "liu_vs_ols without figures (s)"),
    "scenario_liu_vs_ols_s": ("<=", 6, "liu_vs_ols with figures (s)"),
    "scenario_hexapod_paper_s": ("<=", 30, "hexapod_paper (s)"),
}


def meets(op: str, value: float, target: float) -> bool:
    return value >= target if op == ">=" else value <= target


def value_at(out: dict, key: str):
    """The number at a dotted key of bench.json (None where it is not)."""
    v = out
    for k in key.split("."):
        v = v.get(k) if isinstance(v, dict) else None
    return v
