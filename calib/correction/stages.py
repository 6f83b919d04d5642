"""The share of the error each stage of the loop removed: geometry, effect, correction.

On the same readings (the test set when given, else the calibration poses, the correction's
error there held out in the cross-validation), the 3D error per reading of the nominal
model, after the geometric fit, after the named effects and after the residual correction;
each stage's share is the part of the nominal mean square it removed (the shares and what
is left sum to 100 %).
"""

from __future__ import annotations

from pathlib import Path

from common.atomic_files import write_figure_png

STAGES = ("nominal", "geometry", "effect", "correction")


def stage_table(rms_mm: dict[str, float]) -> list[dict]:
    """Rows (stage, rms_mm, share_percent) from each stage's 3D RMS (``STAGES``' keys)."""
    total = rms_mm["nominal"] ** 2
    rows, prev = [], rms_mm["nominal"]
    for stage in STAGES:
        rms = rms_mm[stage]
        share = 0.0 if stage == "nominal" or total == 0 else 100.0 * (prev**2 - rms**2) / total
        rows.append({"stage": stage, "rms_mm": rms, "share_percent": share})
        prev = rms
    rows.append(
        {
            "stage": "left",
            "rms_mm": prev,
            "share_percent": 0.0 if total == 0 else 100.0 * prev**2 / total,
        }
    )
    return rows


def table_lines(rows: list[dict], where: str, effect: str) -> list[str]:
    """The table as printed lines."""
    label = {"effect": f"effect ({effect})"}
    out = [f"share of the nominal mean square each stage removed ({where}):"]
    width = max(34, len(effect) + 10)
    out.append(f"  {'stage':{width}s} {'3D RMS mm':>10s} {'removed':>9s}")
    for r in rows:
        name = label.get(r["stage"], r["stage"])
        share = "" if r["stage"] == "nominal" else f"{r['share_percent']:8.2f}%"
        if r["stage"] == "left":
            name = "left (not removed)"
        out.append(f"  {name:{width}s} {r['rms_mm']:10.4f} {share:>9s}")
    return out


def save_stages_png(rows: list[dict], path: str | Path, title: str) -> Path:
    """Bar chart of each stage's 3D RMS with its share of the nominal mean square."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stages = [r for r in rows if r["stage"] != "left"]
    fig, ax = plt.subplots(figsize=(7, 4))
    names = [r["stage"] for r in stages]
    values = [r["rms_mm"] for r in stages]
    bars = ax.bar(names, values, color=["#9d9d9d", "#4c78a8", "#f58518", "#54a24b"])
    for bar, r in zip(bars, stages, strict=True):
        text = f"{r['rms_mm']:.3g} mm"
        if r["stage"] != "nominal":
            text += f"\nremoved {r['share_percent']:.2f}%"
        ax.annotate(
            text,
            (bar.get_x() + bar.get_width() / 2, bar.get_height()),
            ha="center",
            va="bottom",
            fontsize=8,
        )
    ax.set_ylabel("3D position error per reading, RMS (mm)")
    ax.set_ylim(0, 1.15 * max(values))
    ax.set_xlabel("stage (share: of the nominal mean square, removed by the stage)")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return write_figure_png(fig, path)
