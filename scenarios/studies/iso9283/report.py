"""report.md of the iso9283 scenario."""

from __future__ import annotations

from typing import Any

TITLES = {"hexapod": "The hexapod", "arm": "The 6R arm"}


def _table(m: dict[str, Any]) -> list[str]:
    lines = [
        "| pose | n | AP_P before (mm) | AP_P after (mm) | RP_l (mm) | AP_a/b/c after (deg) "
        "| RP_a/b/c (deg) |",
        "|---|---|---|---|---|---|---|",
    ]
    for pose in m["iso9283"]["poses"]:
        b, a = pose["before"], pose["after"]
        ap = " / ".join(f"{a[k]:+.4f}" for k in ("AP_a_deg", "AP_b_deg", "AP_c_deg"))
        rp = " / ".join(f"{a[k]:.4f}" for k in ("RP_a_deg", "RP_b_deg", "RP_c_deg"))
        lines.append(
            f"| {pose['pose']} | {a['n']} | {b['AP_P_mm']:.4f} | {a['AP_P_mm']:.4f} | "
            f"{a['RP_l_mm']:.4f} | {ap} | {rp} |"
        )
    return lines


def _same(worst: dict[str, Any]) -> str:
    diff = abs(worst["before"]["RP_l_mm"] - worst["after"]["RP_l_mm"])
    if diff > 1e-6:
        return ""
    return (
        " (equal to 1e-6 mm: distances about the barycentre depend neither on the rigid "
        "registration nor on the model)"
    )


def _machine(name: str, m: dict[str, Any]) -> list[str]:
    worst = m["iso9283"]["worst"]
    res = m["calibration_residual"]
    return [
        f"## {TITLES.get(name, name)}",
        "",
        f"Calibrated on {m['n_calibration_poses']} random poses (residual RMS "
        f"{res['rms_mm']:.4f} mm); cube edge {m['cube_edge_mm']:g} mm, {m['cycles']} cycles. "
        f"Exit codes: identify {m['exit_codes']['identify']}, verify "
        f"{m['exit_codes']['verify']}.",
        "",
        *_table(m),
        "",
        f"Worst AP_P: {worst['before']['AP_P_mm']:.4f} mm before, "
        f"{worst['after']['AP_P_mm']:.4f} mm after; worst RP_l "
        f"{worst['before']['RP_l_mm']:.4f} mm before, {worst['after']['RP_l_mm']:.4f} mm "
        f"after{_same(worst)}.",
        "",
    ]


def report(s: dict[str, Any]) -> str:
    rep = s["repeatability"]
    lines = [
        "# ISO 9283 pose accuracy and repeatability, before and after a calibration",
        "",
        "Each machine is calibrated by `pkm-calib identify` on random poses measured by a tracker "
        "in its own frame, then reaches the standard's five cube poses (P1 the centre, P2-P5 "
        "on the diagonal plane at 10 % of its diagonal from the corners) in cycles, and "
        "`pkm-calib verify --iso9283` scores them. Before: the command pose is what the nominal "
        "model predicts; after: what the calibrated one predicts (what compensation would aim "
        "at). The machines' own repeatability in the twin: gaussian "
        f"{rep['position_mm']:g} mm and {rep['rotation_deg']:g} deg per component; tracker "
        f"noise {s['tracker_noise']}.",
        "",
    ]
    for name, m in s["machines"].items():
        lines += _machine(name, m)
    lines += [f"Run time {s['runtime_s']:.1f} s.", ""]
    return "\n".join(lines)
