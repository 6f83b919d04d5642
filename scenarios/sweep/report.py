"""A sweep for a person: report.md with the distributions as figures, and one .rrd with the
runs as a timeline (timeline ``run``: one point per run and number)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.sweep.aggregate import numeric_table, settings_label

PANELS_PER_FIGURE = 12
MAX_FIGURES = 8
MAX_SERIES = 200


def varying_keys(table: dict[str, list[float]]) -> list[str]:
    """Keys whose value differs between runs (a constant draws no distribution)."""
    return [k for k, v in table.items() if len(v) > 1 and np.ptp(v) > 0]


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def _groups(results: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    for r in results:
        if r["status"] == "ok":
            out.setdefault(settings_label(r["spec"]["settings"]), []).append(r["summary"])
    return out


def distribution_pngs(folder: Path, name: str, results: list[dict[str, Any]]) -> list[str]:
    """Histograms of every varying number (one colour per swept setting), 12 to a figure."""
    import matplotlib.pyplot as plt

    from scenarios.figures import save_png

    groups = {k: numeric_table(v) for k, v in _groups(results).items()}
    pooled = numeric_table([s for g in _groups(results).values() for s in g])
    keys = varying_keys(pooled)[: PANELS_PER_FIGURE * MAX_FIGURES]
    written = []
    for f in range(math.ceil(len(keys) / PANELS_PER_FIGURE)):
        chunk = keys[f * PANELS_PER_FIGURE : (f + 1) * PANELS_PER_FIGURE]
        cols = 3
        rows = math.ceil(len(chunk) / cols)
        fig, axes = plt.subplots(
            rows, cols, figsize=(11, 2.6 * rows), constrained_layout=True, squeeze=False
        )
        for ax, key in zip(axes.flat, chunk, strict=False):
            edges = np.histogram_bin_edges(pooled[key], bins=min(30, max(5, len(pooled[key]))))
            for label, table in groups.items():
                if key in table:
                    ax.hist(table[key], bins=edges, alpha=0.55, label=label, edgecolor="k", lw=0.3)
            for q, style in ((5, ":"), (50, "-"), (95, ":")):
                ax.axvline(np.percentile(pooled[key], q), color="k", ls=style, lw=0.8)
            ax.set_title(key, fontsize=8)
            ax.tick_params(labelsize=7)
            if len(groups) > 1:
                ax.legend(fontsize=6)
        for ax in axes.flat[len(chunk) :]:
            ax.axis("off")
        fig.suptitle(f"{name}: distributions over runs (lines: p05, median, p95)", fontsize=10)
        file = f"distributions_{f + 1}.png"
        save_png(fig, folder / file)
        written.append(file)
    return written


def report_markdown(summary: dict[str, Any], figures: list[str]) -> str:
    swept = summary["swept"]
    lines = [
        f"# Sweep: {summary['scenario']}",
        "",
        f"{summary['n_runs']} runs ({summary['n_failed']} failed) on engine "
        f"`{summary['engine']}`; {swept['seeds']} seeds over {swept['over']}"
        + (
            "; settings " + "; ".join(f"`{k}` in {v}" for k, v in swept["settings"].items())
            if swept.get("settings")
            else ""
        )
        + ".",
        "",
    ]
    for f in figures:
        lines += [f"![distributions]({f})", ""]
    sections = {"all runs": summary["metrics"]}
    for label, group in summary.get("by_setting", {}).items():
        sections[label] = group["metrics"]
    for label, metrics in sections.items():
        lines += [
            f"## {label}",
            "",
            "| key | n | median | p05 | p95 | mean | std |",
            "|---|---|---|---|---|---|---|",
        ]
        for k, s in metrics.items():
            stats = " | ".join(_fmt(s[q]) for q in ("median", "p05", "p95", "mean", "std"))
            lines.append(f"| `{k}` | {s['n']} | {stats} |")
        lines.append("")
    failed = [r for r in summary["runs"] if r["status"] != "ok"]
    if failed:
        lines += ["## Failed runs", ""]
        lines += [f"* `{r['run_id']}`: {r['error'].splitlines()[0]}" for r in failed]
        lines.append("")
    return "\n".join(lines)


def record_timeline(path: Path, name: str, results: list[dict[str, Any]], report: str) -> None:
    """Every varying number against the ``run`` timeline (run number in the sweep's order),
    grouped by its top-level key, and the report as text."""
    from scenarios.recording.recorder import Recorder

    ok = [(i, r["summary"]) for i, r in enumerate(results) if r["status"] == "ok"]
    pooled = numeric_table([s for _, s in ok])
    keys = set(varying_keys(pooled)[:MAX_SERIES])
    with Recorder(path, f"pkm-calib-sweep-{name}") as recorder:
        recorder.send_blueprint()
        for i, s in ok:
            for key, value in numeric_table([s]).items():
                if key in keys:
                    recorder.log_points(key.replace(".", "/", 1), "run", i, value[0])
        recorder.log_text("report", report, name="sweep report")
