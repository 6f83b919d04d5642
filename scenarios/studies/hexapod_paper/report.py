"""report.md of the hexapod_paper scenario: our numbers beside the second paper's."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any


def _f(v: Any, digits: int = 4) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


PAPER_TRUTH = "hexapod_table2.toml"  # the file of the paper's Table 2 minus its Table 1
LEVEL = 0.01  # a largest deviation less likely than this under the noise is "larger"


def truth_sentence(source: dict[str, Any] | None, n_parameters: int) -> str:
    """Where the truth came from, as the run says (a values file, or a seeded draw)."""
    if not source:
        return f"Truth: not recorded in this summary ({n_parameters} parameters)."
    if source.get("kind") == "values_file":
        f = str(source.get("file"))
        if Path(f).name == PAPER_TRUTH:
            return (
                f"Truth: the paper's Table 2 (actual parameters) minus Table 1 (nominal), "
                f"{n_parameters} parameters (`{f}`)."
            )
        return f"Truth: the values of `{f}`, {n_parameters} parameters (not the paper's)."
    r = source.get("random") or {}
    spread = ", ".join(f"{k} {v}" for k, v in r.items() if k != "distribution")
    return (
        f"Truth: a random draw (seed {source.get('seed')}, {r.get('distribution', '?')}"
        f"{': ' + spread if spread else ''}) of {n_parameters} parameters, not the paper's "
        "Table 2: the paper's recovery figures do not apply to it."
    )


def largest_deviation_p(z: float, m: int) -> float:
    """The probability that the largest of ``m`` independent Gaussian deviations is at least
    ``z`` standard errors (Sidak): how surprising the worst estimate is under the noise."""
    one = math.erfc(z / math.sqrt(2.0))  # P(|N(0,1)| >= z)
    return float(-math.expm1(m * math.log1p(-min(one, 1.0 - 1e-16))))


ROUND_OFF_MM = 1e-6  # a noise-free recovery below this is exact


def noise_free_sentence(c: dict[str, Any]) -> str:
    """Whether the noise-free case recovered the truth, from its numbers."""
    if "max_abs_mm" not in c:
        return f"* Noise-free: no result ({c.get('error', 'not run')})."
    poses = f"{c['n_poses']} poses x 6 pose components give {6 * c['n_poses']} equations"
    if c["max_abs_mm"] < ROUND_OFF_MM:
        return (
            f"* Noise-free: {poses}, and the identification recovers the errors to round-off "
            f"(largest deviation {c['max_abs_mm']:.1e} mm)."
        )
    return (
        f"* Noise-free: {poses}, yet the identification does not recover the truth: its "
        f"largest deviation is {_f(c['max_abs_mm'])} mm on {c['worst_parameter']} with a "
        f"residual of {_f(c.get('residual_rms_mm'))} mm RMS: "
        + (
            "Levenberg-Marquardt reached another exact root of the equations."
            if (c.get("residual_rms_mm") or 1.0) < ROUND_OFF_MM
            else "the fit stopped short of the truth (see its iterations)."
        )
    )


def deviation_sentence(c: dict[str, Any]) -> str:
    """The worst estimate of a noisy case against the noise, from the case's numbers."""
    z, zmax, m = c.get("worst_over_std"), c.get("max_abs_over_std"), c.get("n_estimated")
    head = (
        f"* {c['n_poses']} noisy poses: the largest deviation, {_f(c['max_abs_mm'])} mm on "
        f"{c['worst_parameter']}, is {_f(z, 3)} standard errors "
        f"({_f(c['worst_std_error_mm'], 3)} mm predicted from the noise and this pose set)"
    )
    if zmax is None or not m:
        return head + "; no standard errors to judge it against."
    p = largest_deviation_p(zmax, m)
    largest = (
        f"the largest of the {m} estimates' deviations is {zmax:.2f} standard errors, "
        f"which the noise alone exceeds with probability {p:.2g}"
    )
    if p >= LEVEL:
        verdict = f"{largest}: consistent with the noise through a poorly conditioned problem"
    else:
        verdict = (
            f"{largest}: larger than linear noise propagation predicts (below {LEVEL:g}); at "
            "this pose count the problem is nonlinear on the scale of its uncertainty, or the "
            "model misses something"
        )
    return f"{head}; {verdict}."


def report(s: dict[str, Any]) -> str:
    paper = s["paper"]
    cases = s["cases"]
    lines = [
        "# Hexapod (6-RRRPRR): the second paper's simulation study",
        "",
        truth_sentence(s.get("truth_source"), s["n_parameters"]),
        "The calibration saw only the nominal MJCF, the error model and the Dataset files in",
        "`datasets/`. Identification: Levenberg-Marquardt on the target residual with the",
        "implicit-function Jacobian of the closed chain.",
        "",
        f"Parameters: {s['n_parameters']}, identifiable from the 256-pose plan: "
        f"{_f(s['n_identifiable'])}. Runtime {s['runtime_s']:.1f} s.",
        "",
        "## Parameter recovery (largest |estimate - truth|, mm)",
        "",
        "| plan | noise | ours | paper | worst parameter | LM iterations | cond (scaled) |",
        "|---|---|---|---|---|---|---|",
    ]
    paper_rec = {
        "noise_free": "exact (Fig. 4a)",
        "random_few": f"about {paper['recovery_29_random_max_abs_mm']}",
        "random_many": f"about {paper['recovery_256_random_max_abs_mm']}",
    }
    for name, c in cases.items():
        if "error" in c:
            lines.append(
                f"| {c['n_poses']} random | {c['noise']} | failed: {c['error'][:80]} "
                f"| {paper_rec[name]} | | | |"
            )
            continue
        lines.append(
            f"| {c['n_poses']} random | {c['noise']} | {_f(c['max_abs_mm'])} | {paper_rec[name]} "
            f"| {c['worst_parameter']} | {c['iterations']} | {_f(c['condition_number'])} |"
        )
    lines += [
        "",
        "## Verification on the 216-pose grid (27 nodes x 8 orientations)",
        "",
        "True tool pose error (no tracker noise) at commanded poses; peak and standard deviation",
        "of the error magnitudes over the poses. A pose whose compensated commands leave a stroke",
        "cannot be reached by the real machine: it is counted, not scored.",
        "",
        "| state | pos peak (mm) | pos std (mm) | ori peak (deg) | ori std (deg) | "
        "poses out of reach |",
        "|---|---|---|---|---|---|",
    ]
    rows = [
        ("before calibration", s.get("verify_before")),
        ("after, 29 random poses", s.get("verify_after_random_few")),
        ("after, 256 random poses", s.get("verify_after")),
    ]
    for label, v in rows:
        if v:
            lines.append(
                f"| {label} | {_f(v['pos_peak_mm'])} | {_f(v['pos_std_mm'])} | "
                f"{_f(v['ori_peak_deg'])} | {_f(v['ori_std_deg'])} | "
                f"{v.get('n_unreachable_after_compensation', 0)} |"
            )
    t6b, t6a = paper["table6_before"], paper["table6_after"]
    lines += [
        f"| paper Table 6, before (experiment) | {t6b['pos_peak_mm']} | {t6b['pos_std_mm']} | "
        f"{t6b['ori_peak_deg']} | {t6b['ori_std_deg']} | |",
        f"| paper Table 6, after (experiment) | {t6a['pos_peak_mm']} | {t6a['pos_std_mm']} | "
        f"{t6a['ori_peak_deg']} | {t6a['ori_std_deg']} | |",
        f"| paper Table 4, before (simulation, 29 poses) | "
        f"{paper['table4_before']['pos_peak_mm']} | {paper['table4_before']['pos_std_mm']} | | | |",
        f"| paper Table 4, after 256 random (simulation) | "
        f"{paper['table4_after_256_random']['pos_peak_mm']} | "
        f"{paper['table4_after_256_random']['pos_std_mm']} | | | |",
        "",
    ]
    export = s.get("export")
    if export:
        lines += [
            f"The compensated commands come from the pose-by-pose solve `pkm-calib "
            f"compensate` uses. The calibrated model (256 random poses) written into the MJCF as "
            f"`pkm-calib export` writes it ({export['file']}) differs from the identified "
            f"model's forward kinematics by at most {export['max_fk_diff_mm']:.2g} mm over "
            f"{export['n_commands']} commands (the grid's nominal and compensated ones).",
            "",
        ]
    lines += [
        "## Why the numbers differ from the paper",
        "",
        noise_free_sentence(cases.get("noise_free", {})),
    ]
    for name in ("random_few", "random_many"):
        c = cases.get(name, {})
        if "max_abs_mm" not in c:
            continue
        corr = c.get("strongest_correlations") or []
        pairs = ", ".join(f"{p['a']} ~ {p['b']} ({p['correlation']:+.3f})" for p in corr)
        lines.append(f"{deviation_sentence(c)} Most correlated estimates: {pairs}.")
    lines += [
        "* The paper reports about 1.1 mm after 29 poses and about 15 um after 256; the",
        "  conditioning of the 54-parameter problem under its stated noise does not allow the",
        "  latter (nearly collinear columns, above). The poses, which are what a user needs, come",
        "  out accurate to about 0.01 mm, as in its Tables 4 and 6.",
        "* The paper's Table 6 is an experiment on the real machine (before: its own",
        "  unknown errors), not the Table 2 truth used here; Table 4 is its simulation but",
        "  scored on its 29 calibration poses, not on a separate verification grid.",
        "",
    ]
    for name, path in (s.get("figures") or {}).items():
        lines += [f"![{name}]({path})", ""]
    est = s.get("estimates_random_many")
    if est:
        lines += [
            "## Estimates from 256 random poses (mm)",
            "",
            "| parameter | truth | estimate | std error |",
            "|---|---|---|---|",
        ]
        for n, e in est.items():
            lines.append(
                f"| {n} | {e['truth_mm']:.3f} | {e['estimate_mm']:.4f} | {_f(e['std_mm'], 3)} |"
            )
        lines.append("")
    return "\n".join(lines)
