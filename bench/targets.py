"""What ``make bench`` holds its numbers to: key in bench.json -> (comparison, target, what it
is). A target whose number the run did not measure is left out of ``meets_targets``."""

from __future__ import annotations

Target = tuple[str, float, str]


def _machine_targets(m: str) -> dict[str, Target]:
    """identify against scipy's least_squares on machine ``m`` of bench.machines."""
    speed = "identify's speedup vs scipy least_squares"
    return {
        f"machines.{m}.identify_speedup_vs_scipy_fd": (">=", 15, f"{speed} (FD Jacobian), {m}"),
        f"machines.{m}.identify_speedup_vs_scipy_analytic": (
            ">=",
            1,
            f"{speed} (our analytic Jacobian), {m}",
        ),
    }


def _campaign_targets(m: str) -> dict[str, Target]:
    """A campaign's time and memory on machine ``m`` of bench.scaling."""
    at = f"scaling.{m}.by_readings"
    return {
        f"scaling.{m}.ratios.identify_10k_over_1k.time": (
            "<=",
            15,
            f"identify's time, 10k over 1k readings, {m}",
        ),
        f"{at}.100000.identify.peak_mb": ("<=", 4096, f"identify's peak MB, 100k readings, {m}"),
        f"{at}.10000.identify.peak_mb": ("<=", 1536, f"identify's peak MB, 10k readings, {m}"),
        f"{at}.10000.diagnose.peak_mb": ("<=", 2048, f"diagnose's peak MB, 10k readings, {m}"),
        f"scaling.{m}.diagnose_over_identify.10000": (
            "<=",
            6,
            f"diagnose's time over identify's, 10k readings, {m}",
        ),
    }


TARGETS: dict[str, Target] = {
    "machines.hexapod.fk_batch_poses_per_s": (">=", 50000, "batched FK poses/s, hexapod"),
    **{k: t for m in ("hexapod", "polisher", "arm") for k, t in _machine_targets(m).items()},
    "command_line.identify_over_import": (
        "<=",
        2,
        "identify on a 20-pose arm over the bare import of the command line",
    ),
    **{k: t for m in ("arm", "hexapod") for k, t in _campaign_targets(m).items()},
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
