"""report.md of the undeclared_effect scenario."""

from __future__ import annotations

from typing import Any


def report(s: dict[str, Any]) -> str:
    lines = [
        "# Closing the loop: a residual that geometry leaves",
        "",
        f"Effects in the truth (not declared to the calibration): {s['effects_in_truth']}.",
        "",
        f"Residual after geometric calibration: {s['residual_rms_before_mm']:.4f} mm RMS per "
        f"coordinate, against a tracker noise floor of {s['noise_floor_rms_mm']:.4f} mm "
        f"(chi-square p = {s['chi2_p_value']:.3g}).",
        "",
        f"**Diagnosis: {s['diagnosed_effect']}** — {s['reason']}.",
        "",
        "| candidate | held-out RMS (mm) |",
        "|---|---|",
        *[f"| {n} | {v:.5f} |" for n, v in s["candidates"].items()],
        "",
        "Structure of the geometric residual (rank correlation of each pose's residual with): "
        + ", ".join(f"{k} {v:+.2f}" for k, v in s.get("residual_structure", {}).items()),
        "",
        f"With the effect added: residual {s['residual_rms_after_mm']:.4f} mm RMS.",
        "",
        "Test poses not used to fit (pose predicted from the commands against the measured one):",
        "",
        "| model | pos max (mm) | pos mean (mm) | ori max (deg) | ori mean (deg) |",
        "|---|---|---|---|---|",
    ]
    for label, v in s["test"].items():
        lines.append(
            f"| {label} | {v['pos_max_mm']:.4f} | {v['pos_mean_mm']:.4f} | "
            f"{v['ori_max_deg']:.5f} | {v['ori_mean_deg']:.5f} |"
        )
    lines.append("")
    return "\n".join(lines)
