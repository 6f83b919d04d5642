"""results/bench.md: every number of bench.json, with its target and whether it is met."""

from __future__ import annotations

from bench.targets import TARGETS, value_at


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return f"{v:.4g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.2e}"
    return str(v)


def bench_markdown(out: dict) -> str:
    lines = [
        "# make bench",
        "",
        f"{out['cpu_count']} CPUs; a shared machine's timings are noisy, so compare ratios "
        "measured in the same run. Written with bench.json by `python -m bench`.",
        "",
        "## Targets",
        "",
        "| number | value | target | met |",
        "|---|---|---|---|",
    ]
    for key, target in out["targets"].items():
        op, _, label = TARGETS.get(key, ("", None, key))
        value = value_at(out, key)
        met = out["meets_targets"].get(key)
        met_text = "not measured" if met is None else ("met" if met else "**not met**")
        lines.append(f"| {label} (`{key}`) | {_fmt(value)} | {op} {target} | {met_text} |")
    for key, why in out.get("not_measured", {}).items():
        lines.append(f"| `{key}` | - | {why} | not measured |")
    machines = out["machines"]
    names = list(machines)
    keys = [k for k in machines[names[0]] if k != "poses"]
    lines += [
        "",
        "## Machines",
        "",
        "Ours: calib.fit.identification (robust, the default; `plain` is robust=False), fresh model, best "  # noqa: E501
        f"of {machines[names[0]].get('identify_ours_repeats')}. Baseline: "
        f"`scipy.optimize.least_squares({out['scipy_options']})` over the same identified "
        "parameters on a fresh model, best of `identify_scipy_fd_runs`. Differences in mm "
        "(lengths) and deg (angles) over the identified parameters.",
        "",
        "| number | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for k in keys:
        lines.append(f"| {k} | " + " | ".join(_fmt(machines[n].get(k)) for n in names) + " |")
    lines.append("| poses | " + " | ".join(machines[n]["poses"] for n in names) + " |")
    lines += _scaling_lines(out.get("scaling", {}))
    lines += ["", "## Scenarios (whole runs, temporary results root)", ""]
    lines += ["| scenario | seconds |", "|---|---|"]
    for k, v in out.items():
        if k.startswith("scenario_") and k.endswith("_s"):
            lines.append(f"| {k[len('scenario_') : -2]} | {_fmt(v)} |")
    for name in out.get("scenarios_skipped", []):
        lines.append(f"| {name} | not run (BENCH_ALL=1 runs it) |")
    for name, error in out.get("scenario_errors", {}).items():
        lines.append(f"| {name} | failed: {error.splitlines()[0][:200]} |")
    lines.append("")
    return "\n".join(lines)


def _scaling_lines(scaling: dict) -> list[str]:
    """What a campaign of N readings costs: the command line's wall time and peak memory."""
    if not scaling:
        return []
    lines = [
        "",
        "## Campaign size (the command line, a fresh process each)",
        "",
        "| machine | readings | identify s | identify MB | diagnose s | diagnose MB |",
        "|---|---|---|---|---|---|",
    ]
    for machine, block in scaling.items():
        for n, row in block["by_readings"].items():
            cells = []
            for cmd in ("identify", "diagnose"):
                r = row.get(cmd)
                cells += [_fmt(r["wall_s"]), _fmt(r["peak_mb"])] if r else ["-", "-"]
            lines.append(f"| {machine} | {n} | " + " | ".join(cells) + " |")
    lines += ["", "| machine | ratio | time | memory |", "|---|---|---|---|"]
    for machine, block in scaling.items():
        for key, r in block["ratios"].items():
            lines.append(f"| {machine} | {key} | {_fmt(r['time'])} | {_fmt(r['memory'])} |")
        for n, r in block.get("diagnose_over_identify", {}).items():
            lines.append(f"| {machine} | diagnose over identify, {n} readings | {_fmt(r)} | - |")
    return lines
