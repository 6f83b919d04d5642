"""report.md of the measured_loop scenario: every sentence from the run's numbers."""

from __future__ import annotations

from typing import Any


def _pair(block: dict[str, Any] | None) -> str:
    if not block:
        return "-"
    b, a = block["before"], block["after"]
    return f"{b['rms_mm']:.4f} / {b['max_mm']:.4f} -> {a['rms_mm']:.4f} / {a['max_mm']:.4f}"


def _diagnosis_sentence(s: dict[str, Any]) -> str:
    d = s["diagnosis"]
    named = d["named"]
    if named == "none":
        return "The diagnosis found nothing beyond the tracker noise: " + d["reason"] + "."
    if named.startswith("unexplained"):
        return f"The diagnosis found structure no candidate explains: {d['reason']}."
    t = d.get("test")
    held = ""
    if t:
        held = (
            f" On the held-out test set it takes the 3D RMS from {t['before']['rms_mm']:.4f} "
            f"to {t['after']['rms_mm']:.4f} mm and the max from {t['before']['max_mm']:.4f} "
            f"to {t['after']['max_mm']:.4f} mm."
        )
    tail = ""
    if d["not_static"]:
        why = "; ".join(f"{n}: {r}" for n, r in d["not_static_reasons"].items())
        tail = (
            f" It is no static kind of the error model ({why}): its before and after above "
            "are the diagnosis's own, and `identify --with` cannot add it."
        )
    return f"The diagnosis names **{named}**: {d['reason']}.{held}{tail}"


def _refit_sentence(w: dict[str, Any]) -> str:
    params = w.get("parameters") or {}
    shown = ", ".join(
        f"{n} = {p['value']:.4g}"
        + (f" +- {p['std']:.2g}" if p.get("std") is not None else "")
        + f" {p['unit']}"
        for n, p in params.items()
    )
    verdict = (w.get("verdict") or {}).get("message", "")
    return (
        f"**Identify --with.** The effect's parameters refitted with the geometry: {shown}. "
        f"{verdict}"
    )


def _to_the_machine(s: dict[str, Any]) -> list[str]:
    """The program compensated through the result with its effect, and the exported model."""
    lines = []
    p = s.get("program")
    if p:
        b, a = p["before"], p["after"]
        joint, change = max(p["max_joint_change"].items(), key=lambda kv: kv[1])
        m = p["after_mean_in_tool_frame_mm"]
        lines += [
            f"**To the machine.** `pkm-calib compensate --commands` corrected a program of "
            f"{p['n_targets']} joint targets through the result with its effect (exit code "
            f"{p['exit_code']}, {p['n_written']} written); the twin, compliance and all, moved "
            f"to them: the true tool point's error against the nominal intent (tracker frame) "
            f"went from {b['rms_mm']:.3f} / {b['max_mm']:.3f} mm (RMS / max) at the program's "
            f"commands to {a['rms_mm']:.4f} / {a['max_mm']:.4f} mm at the corrected ones, of "
            f"which ({m[0]:+.4f}, {m[1]:+.4f}, {m[2]:+.4f}) mm is one offset in the tool's "
            f"frame (the tool point no reflector sees) and {p['after_spread_about_it_mm']:.4f} "
            f"mm RMS the spread about it; the largest joint change was {joint} "
            f"{change:.3f} deg.",
            "",
        ]
    e = s.get("export")
    if e:
        lacks = e.get("model_lacks")
        t = e["verify_as_is_test"]
        rms = "-" if t.get("rms_mm") is None else f"{t['rms_mm']:.4f}"
        lines += [
            "`pkm-calib export` wrote the calibrated MJCF (exit code "
            f"{e['exit_codes']['export']}); "
            f"`pkm-calib verify --model` of it as it is scores the test set at {rms} mm RMS (exit "
            f"code {e['exit_codes']['verify_as_is']}), "
            + (f"and says first: {lacks}" if lacks else "and the file holds every parameter."),
            "",
        ]
    return lines


def report(s: dict[str, Any]) -> str:
    v = s["verdict"]
    codes = ", ".join(f"{k} {c}" for k, c in s["exit_codes"].items())
    lines = [
        "# The loop on a machine with real characteristics",
        "",
        "A cobot-like 6R arm with three reflectors, its joints winding up under a payload "
        f"({', '.join(s['effects']) or 'no effect'} in the twin; the calibration is not told), "
        f"measured by a tracker in its own frame that declares {s['sigma_mm']:g} mm per "
        f"coordinate: {s['n_poses']['calibration']} calibration and {s['n_poses']['test']} "
        "test poses in one file, and the commands a user types (their logs beside this "
        f"report). Exit codes: {codes}.",
        "",
        "Metric: the 3D position error of each reading |p_measured - p_model| (mm).",
        "",
        f"**Identify.** {v['message']}",
        "",
        f"Weak directions: {s['regularisation']['text']}.",
        "",
        "| model | test RMS / max before -> after (mm) |",
        "|---|---|",
        f"| geometry | {_pair(s['test'])} |",
        f"| geometry, then the diagnosis's effect | {_pair(s['diagnosis'].get('test'))} |",
    ]
    if "with_effect" in s:
        lines.append(
            "| geometry and effect refitted (identify --with) | "
            f"{_pair(s['with_effect']['test'])} |"
        )
    lines += [
        "",
        "**Diagnose.** " + _diagnosis_sentence(s),
        "",
    ]
    if "with_effect" in s:
        lines += [_refit_sentence(s["with_effect"]), ""]
    lines += _to_the_machine(s)
    lines += [
        f"Run time {s['runtime_s']:.1f} s.",
        "",
    ]
    return "\n".join(lines)
