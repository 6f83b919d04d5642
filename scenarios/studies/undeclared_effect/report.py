"""report.md of the undeclared_effect scenario."""

from __future__ import annotations

from typing import Any

from scenarios.files_loop import files_loop_sentence


def report(s: dict[str, Any]) -> str:
    lines = [
        "# Closing the loop: a residual that geometry leaves",
        "",
        "Effects in the truth (not declared to the calibration): "
        f"{', '.join(s['effects_in_truth']) or 'none'}.",
        "",
        f"Residual after geometric calibration: {s['residual_rms_before_mm']:.4f} mm RMS per "
        f"coordinate, against a tracker noise floor of {s['noise_floor_rms_mm']:.4f} mm "
        f"(chi-square p = {s['chi2_p_value']:.3g}).",
        "",
        f"**Diagnosis: {s['diagnosed_effect']}** — {s['reason']}.",
        "",
    ]
    if s.get("figure"):
        lines += [
            f"Each pose's residual (RMS per coordinate) against {s['plot_variable']}, after "
            "the geometric fit and with the named effect:",
            "",
            f"![residual against {s['plot_variable']}]({s['figure']})",
            "",
        ]
    noise = s["noise_floor_rms_mm"]
    lines += [
        "Held-out RMS per coordinate of each candidate alone beside the geometry (nested "
        "cross-validation), and over the noise (the recording's bar chart shows log2 of "
        "that ratio, so one far-off candidate does not flatten the others):",
        "",
        "| candidate | held-out RMS (mm) | / noise |",
        "|---|---|---|",
        *[f"| {n} | {v:.5f} | {v / noise:.2f} |" for n, v in s["candidates"].items()],
        "",
        "Structure of the geometric residual (rank correlation of each pose's residual with): "
        + ", ".join(f"{k} {v:+.2f}" for k, v in s.get("residual_structure", {}).items()),
        "",
        f"With the effect added: residual {s['residual_rms_after_mm']:.4f} mm RMS.",
        "",
        "Test poses not used to fit, 3D position error per reading (mm):",
        "",
        "| model | RMS | mean | max |",
        "|---|---|---|---|",
        *[
            f"| {label} | {v['rms_mm']:.4f} | {v['mean_mm']:.4f} | {v['max_mm']:.4f} |"
            for label, v in s.get("test_3d", {}).items()
        ],
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
    through = files_loop_sentence(
        s.get("loop_through_files"), s.get("test_3d", {}).get("after", {}).get("rms_mm")
    )
    if through:
        lines += [through, ""]
    return "\n".join(lines)
