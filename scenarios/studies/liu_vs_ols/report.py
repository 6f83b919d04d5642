"""report.md of the liu_vs_ols study: our Table 5 beside the paper's, eta, the loop, the draws.

The sentences that judge the run are made from its numbers (scenarios.studies.liu_vs_ols.sentences).
"""

from __future__ import annotations

import math
from typing import Any

from scenarios.files_loop import files_loop_sentence
from scenarios.studies.liu_vs_ols.combinations import sentence as plan_sentence
from scenarios.studies.liu_vs_ols.sentences import (
    effects_phrase,
    estimator_parameters,
    eta_sentences,
    loop_sentence,
    reproduction_sentences,
    scoring_sentences,
)

ORDER = (
    "uncalibrated",
    "coarse",
    "ols",
    "liu",
    "liu_k1",
    "liu_paper_deg",
    "liu_paper_rad",
    "liu_cv",
    "ridge",
    "pcr",
    "loop",
    "ols_again",
)
PAPER_ROW = {"coarse": "coarse", "ols": "ols", "liu_paper_deg": "liu"}
# How the tables name a stage: the Liu-type estimator with the HKB k is not the paper's Liu.
SHOWN = {
    "liu": "liu (HKB k)",
    "liu_k1": "liu_k1 (k = 1, scaled H)",
    "liu_paper_deg": "liu_paper_deg (paper's Liu)",
    "liu_cv": "liu_cv (k, d by CV)",
    "ols_again": "ols_again (control)",
}


def shown(stage: str) -> str:
    return SHOWN.get(stage, stage)


def paper_row(row: str) -> str:
    """A row of the paper's Table 5 and the stage of ours set beside it."""
    ours = {v: k for k, v in PAPER_ROW.items()}.get(row, row)
    return row if ours == row else f"{row} (ours: {ours})"


GROUP_TITLE = {
    "all": "all three layers (as the paper's Table 5)",
    "test": "test layer (middle, z = 0)",
    "calibration": "calibration layers (upper and lower)",
}


def _f(v: Any, fmt: str = ".4f") -> str:
    return "-" if v is None else format(v, fmt)


def _table(group: str, stages: dict[str, dict[str, float]], paper: dict[str, Any]) -> list[str]:
    lines = [
        f"### {GROUP_TITLE.get(group, group)}",
        "",
        "| stage | pos max (mm) | pos mean (mm) | ori max (deg) | ori mean (deg) "
        "| paper pos max | paper pos mean | paper ori max | paper ori mean |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for stage in [s for s in ORDER if s in stages] + [s for s in stages if s not in ORDER]:
        v = stages[stage]
        p = paper["table5"].get(PAPER_ROW.get(stage, ""), {})
        lines.append(
            f"| {shown(stage)} | {v['pos_max_mm']:.4f} | {v['pos_mean_mm']:.4f} | "
            f"{v['ori_max_deg']:.4f} | {v['ori_mean_deg']:.4f} | "
            + " | ".join(
                _f(p.get(q), ".3f")
                for q in ("pos_max_mm", "pos_mean_mm", "ori_max_deg", "ori_mean_deg")
            )
            + " |"
        )
    return [*lines, ""]


def _match(s: dict[str, Any]) -> list[str]:
    m = s["paper_match"]
    lines = [
        "## The paper's regime: coarse and OLS rows matched, Liu predicted",
        "",
        f"Tolerance: ours / paper within a factor {m['position_factor']} for the position max "
        "and mean of the coarse and OLS rows, all three layers "
        f"(reproduced: **{m['position_reproduced']}**).",
        "",
        "| row | pos max ratio | pos mean ratio | ori max ratio | ori mean ratio |",
        "|---|---|---|---|---|",
    ]
    for stage, r in m["rows"].items():
        q = r["ratio"]
        lines.append(
            f"| {paper_row(stage)} | {q['pos_max_mm']:.2f} | {q['pos_mean_mm']:.2f} | "
            f"{q['ori_max_deg']:.2f} | {q['ori_mean_deg']:.2f} |"
        )
    return [*lines, ""]


def _orientation(s: dict[str, Any]) -> list[str]:
    """Why the orientation rows are not matched, from the orientation reach in the summary."""
    r = s.get("orientation_reach")
    if not r:
        return []
    lines = [
        "## Can the paper's orientation rows come from the machine?",
        "",
        "Not from one effect of it. An effect acting through one joint or link (backlash, a "
        "transmission or encoder error, compliance, thermal growth or lead error of a limb) "
        "turns the head by that source error's twist, and the geometry fixes how far the head "
        "turns per millimetre it moves the tool point P. Over the test layer's poses, on the "
        "controller's model: the largest median of any of the "
        f"{s['n_source_errors']} source errors is {r['largest_median_deg_per_mm']:.3f} deg/mm "
        f"({r['largest_source_error']}); of the motions of the actuated joints, "
        f"{r['largest_joint_motion_median_deg_per_mm']:.3f} deg/mm "
        f"({r['largest_joint_motion']}, the wrist axis nearest P).",
        "",
        "| joint motion | median (deg/mm) | max (deg/mm) | equivalent lever to P (mm) |",
        "|---|---|---|---|",
    ]
    for name, v in r["joint_motions"].items():
        lever = math.degrees(1.0) / v["median_deg_per_mm"]  # mm
        lines.append(
            f"| {name} | {v['median_deg_per_mm']:.4f} | {v['max_deg_per_mm']:.4f} | {lever:.0f} |"
        )
    lines += [
        "",
        "| row (all layers) | paper max (deg/mm) | paper mean | ours max | ours mean |",
        "|---|---|---|---|---|",
    ]
    for stage, v in r["rows"].items():
        lines.append(
            f"| {paper_row(stage)} | {v['paper_max_deg_per_mm']:.2f} | "
            f"{v['paper_mean_deg_per_mm']:.2f} | "
            f"{_f(v['ours_max_deg_per_mm'], '.3f')} | {_f(v['ours_mean_deg_per_mm'], '.3f')} |"
        )
    lines += [
        "",
        "The paper's rows turn the head by about 1 deg per mm of position error, three to four "
        "times the median of even the wrist axis nearest P, and some ten times what the "
        "twin's rows show. Only errors of several joints that happen to cancel at P (a rotation "
        "about P itself), or errors of the measured orientation (the gauge and the metric of its "
        "Eq. 9), would reach the paper's ratio; none of them is a stated effect of the machine, "
        "so the twin does not invent one, and the tolerance gates position only.",
        "",
    ]
    return lines


def _loop(s: dict[str, Any]) -> list[str]:
    lp = s["loop"]
    lines = [
        "## The loop: diagnosis, the effect in the model, refit, compensation",
        "",
        f"Diagnosed effect: **{lp['diagnosed_effect']}** ({lp['reason']}). Residual of the fine "
        f"calibration data, 3D RMS per reading: {lp['residual_rms_before_mm']:.4f} mm after the "
        f"fine OLS, {lp['residual_rms_after_mm']:.4f} mm "
        + (
            "with the effect modelled and geometry and effect refitted together"
            if lp["coefficients"]
            else "with no effect to model: the nonlinear refit of the geometry alone"
        )
        + f" (Levenberg-Marquardt, {lp['lm_iterations']} iterations); noise floor sqrt(3) "
        f"sigma = {lp['noise_floor_rms_mm']:.4f} mm (3D RMS per reading). " + loop_sentence(s),
        "",
        "| coefficient | value (SI) | std (SI) |",
        "|---|---|---|",
    ]
    for n, v in lp["coefficients"].items():
        lines.append(f"| {n} | {v:.4g} | {lp['coefficient_std'].get(n, float('nan')):.2g} |")
    through = files_loop_sentence(s.get("loop_through_files"))
    if through:  # the fine readings and the test layer's, handed over as a Dataset file
        lines += ["", "The fine readings and the test layer's nodes as a Dataset file: " + through]
    return [*lines, ""]


def _draws_ref(d: dict[str, Any]) -> list[str]:
    lines = ["## Liu against OLS over many truths", ""]
    if not d.get("n"):
        return [*lines, d.get("note", "not run"), ""]
    said = [
        f"From the draw study ({d.get('source', '')}), {d['n']} truth draws, every stage "
        "scored on the same machine state; estimator minus OLS in the test layer's mean "
        "position error:"
    ]
    for label in ("liu_paper_deg", "liu", "liu_cv"):
        m = d.get(f"{label}_minus_ols_test_pos_mean_mm")
        if m:
            said.append(
                f"`{shown(label)}` median {m['median'] * 1e3:+.3g} um (5-95 %: "
                f"{m['p05'] * 1e3:+.3g} .. {m['p95'] * 1e3:+.3g} um), better in "
                f"{d[f'{label}_better_fraction'] * 100:.0f} % of draws;"
            )
    return [*lines, " ".join(said).rstrip(";") + ".", ""]


def truth_text(random: Any) -> str:
    """The drawn source errors as a reader reads them (not a Python dict)."""
    if not isinstance(random, dict):
        return "from the scenario's values file"
    units = {
        "translation_mm": "mm",
        "rotation_deg": "deg",
        "encoder_mm": "mm",
        "encoder_deg": "deg",
    }
    words = {
        "translation_mm": "translations",
        "rotation_deg": "rotations",
        "encoder_mm": "linear encoder offsets",
        "encoder_deg": "angular encoder offsets",
    }
    kind = random.get("distribution", "uniform")
    parts = [f"{words[k]} +-{random[k]:g} {units[k]}" for k in words if k in random]
    return f"drawn {kind} ({', '.join(parts)})"


def _report_draws(s: dict[str, Any]) -> str:
    d = s["draws"]
    lines = [
        "# Hybrid polisher: Liu against OLS over many truth draws",
        "",
        f"{d['n']} truth draws (seeds {d['seeds'][0]}..{d['seeds'][1]}), effects "
        f"{', '.join(s['truth_effects']) or 'none'}; engine {s['engine']}; runtime "
        f"{s['runtime_s']:.0f} s. Differences in um, estimator minus OLS (below 0: better "
        "than OLS); 'better' is the fraction of draws with a lower mean position error. "
        "`liu_paper_deg` is the paper's estimator (Eq. 11 with k = 1 on H in mm and deg, d from "
        "Eq. 14, sigma^2 = RSS / n as Eq. 13 writes it); `liu` is the Liu-type estimator with "
        "the Hoerl-Kennard-Baldwin k on the column-scaled H (not the paper's).",
        "",
        *_draws_scoring(s),
        "| layers | estimator | mean: median | p05 | p95 | max: median | p05 | p95 "
        "| better (mean) | better (max) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for g, block in d["groups"].items():
        for est, e in block.items():
            if "minus_ols_pos_mean_mm" not in e:
                continue
            a, b = e["minus_ols_pos_mean_mm"], e["minus_ols_pos_max_mm"]
            lines.append(
                f"| {g} | {shown(est)} | {a['median'] * 1e3:.3g} | {a['p05'] * 1e3:.3g} | "
                f"{a['p95'] * 1e3:.3g} | {b['median'] * 1e3:.3g} | {b['p05'] * 1e3:.3g} | "
                f"{b['p95'] * 1e3:.3g} | {e['better_fraction']:.2f} | "
                f"{e['better_fraction_max']:.2f} |"
            )
    lines += [
        "",
        "## The rows over the draws (all three layers; paper beside)",
        "",
        "| stage | pos max median (p05..p95) mm | pos mean median (p05..p95) mm "
        "| paper max | paper mean |",
        "|---|---|---|---|---|",
    ]
    paper = s["paper"]["table5"]
    for est, e in d["groups"]["all"].items():
        mx, mn = e["pos_max_mm"], e["pos_mean_mm"]
        p = paper.get(PAPER_ROW.get(est, ""), {})
        lines.append(
            f"| {shown(est)} | {mx['median']:.4f} ({mx['p05']:.4f}..{mx['p95']:.4f}) | "
            f"{mn['median']:.4f} ({mn['p05']:.4f}..{mn['p95']:.4f}) | "
            f"{_f(p.get('pos_max_mm'), '.3f')} | {_f(p.get('pos_mean_mm'), '.3f')} |"
        )
    reg = s.get("paper_regime")
    if reg:
        lines += [
            "",
            f"Draws whose coarse and OLS rows both lie within a factor {reg['position_factor']} "
            f"of the paper's (position max and mean): {reg['both_rows_within_fraction']:.0%} "
            f"(coarse {reg['coarse_within_fraction']:.0%}, OLS {reg['ols_within_fraction']:.0%}).",
        ]
    lines.append("")
    for name, path in (s.get("figures") or {}).items():
        lines.append(f"![{name}]({path})")
    return "\n".join(lines) + "\n"


def _draws_scoring(s: dict[str, Any]) -> list[str]:
    sc = s.get("scoring")
    if not sc:
        return []
    c = sc["order_control_um"]
    return [
        "Every stage of a draw was scored from the same clock (its machine state); the "
        f"control 'ols_again' (OLS scored after every other stage) differs from OLS by at "
        f"most {c:.3g} um in the test layer's mean over the draws"
        + (": within round-off." if c < 0.05 else ": NOT within round-off."),
        "",
    ]


def report(s: dict[str, Any]) -> str:
    if s.get("study") == "liu_vs_ols_draws":
        return _report_draws(s)
    paper = s["paper"]
    est = s.get("estimators", {})
    liu_dk = estimator_parameters(s.get("liu_bias_d"), s.get("liu_k"))
    paper_dk = estimator_parameters(
        est.get("liu_paper_deg", {}).get("bias_parameter"),
        est.get("liu_paper_deg", {}).get("scale_parameter"),
    )
    effects = s["truth_effects"]
    lines = [
        "# Hybrid polisher: coarse then fine calibration, Liu against OLS",
        "",
        f"Truth: source errors {truth_text(s.get('truth_random'))}; effects "
        + (
            f"{', '.join(effects)} ({effects_phrase(effects)})"
            if effects
            else "none (geometry only)"
        )
        + f". Source errors: {s['n_source_errors']} (paper: {paper['n_source_errors']}); "
        f"identifiable from the fine plan (Steps 1-3): {s['n_identifiable']} (paper: "
        f"{paper['n_identifiable']}). Coarse calibration: {s['coarse_iterations']} rounds "
        f"(converged: {s['coarse_converged']}). Runtime {s['runtime_s']:.1f} s.",
        "",
        "Estimators: `liu_paper_deg` is the paper's Liu estimator, Eq. 11 literally (k = 1) on H "
        "in mm and deg, d from Eq. 14 with sigma^2 = RSS / n (Eq. 13)"
        + (f": {paper_dk}" if paper_dk else "")
        + "; `liu_paper_rad` the same in mm and rad. `liu` (HKB k) is the Liu-type estimator "
        "with the unit-free Hoerl-Kennard-Baldwin scale k and the MSE-optimal d (Eq. 14 "
        "generalised) on the column-scaled H"
        + (f": {liu_dk}" if liu_dk else "")
        + "; `liu_k1` is Eq. 11 with k = 1 on the scaled H. `loop` is the fine OLS followed by "
        "the diagnosed effect (below); `ols_again` (control) is OLS's commands scored once "
        "more after every other stage.",
        "",
        *scoring_sentences(s),
        "## Pose errors (true pose of the head at every node), paper's Table 5 beside",
        "",
    ]
    for group in ("all", "test", "calibration"):
        if group in s["layers"]:
            lines += _table(group, s["layers"][group], paper)
    if "paper_match" in s:
        lines += _match(s)
    lines += reproduction_sentences(s)
    lines += _orientation(s)
    lines += eta_sentences(s)
    if "loop" in s:
        lines += _loop(s)
    if "draws" in s:
        lines += _draws_ref(s["draws"])
    figs = s.get("figures") or {}
    if figs:
        lines += ["## Error maps and estimates", ""]
        for label, entry in (s.get("plan_combinations") or {}).items():
            lines += [f"Estimates of `{label}`: {plan_sentence(entry)}", ""]
        lines += [f"![{name}]({path})" for name, path in figs.items()]
        lines.append("")
    return "\n".join(lines)
