"""report.md of the diagnosis_benchmark scenario: the confusion table and the goal's rates."""

from __future__ import annotations

from typing import Any


def _pct(v: float | None) -> str:
    return "n/a" if v is None else f"{100 * v:.0f} %"


def _figure(s: dict[str, Any], name: str, alt: str) -> list[str]:
    file = (s.get("figures") or {}).get(name)
    return [f"![{alt}]({file})", ""] if file else []


def confusion_table(confusion: dict[str, dict[str, int]]) -> list[str]:
    """Markdown rows: true kind (rows) -> named effect (columns), counts."""
    named = sorted({n for row in confusion.values() for n in row})
    lines = [
        "| true kind \\ named | " + " | ".join(named) + " |",
        "|---|" + "---|" * len(named),
    ]
    for kind in sorted(confusion):
        row = confusion[kind]
        lines.append(f"| {kind} | " + " | ".join(str(row.get(n, "")) for n in named) + " |")
    return lines


def _count(rate: float | None, n: int) -> int:
    """The count behind a rate of n cases (the rates are counts over n, stored as floats)."""
    return 0 if rate is None or n == 0 else round(rate * n)


def absorbed_sentence(s: dict[str, Any]) -> str:
    """The rate with the absorbed cases counted as misses, and with them scored by what was
    named for them (``correct_rate_with_absorbed``), both from the counts behind the rates."""
    n_strong, n_absorbed = s["n_correct_rate_cases"], s.get("n_absorbed", 0)
    if not n_absorbed:
        return "no case to count as a miss"
    n_all = n_strong + n_absorbed
    right = _count(s["correct_rate"], n_strong)
    right_all = _count(s.get("correct_rate_with_absorbed"), n_all)
    named_right = right_all - right
    return (
        f"counting them as misses the rate would be {right}/{n_all} = {_pct(right / n_all)}; "
        f"scored by what was named for them ({named_right} of {n_absorbed} named right), "
        f"{right_all}/{n_all} = {_pct(right_all / n_all)}"
    )


def report(s: dict[str, Any]) -> str:
    goal = s["goal"]
    ok = (
        s["correct_rate"] is not None
        and s["correct_rate"] >= goal["correct_rate_min"]
        and (s["false_alarm_rate"] or 0.0) <= goal["false_alarm_rate_max"]
        and s["heldout_worse_count"] <= goal["heldout_worse_count_max"]
    )
    lines = [
        "# Diagnosis benchmark: many random truths, one undeclared effect each",
        "",
        f"{s['n_cases']} cases on {', '.join(s['models'])}; runtime {s['runtime_s']:.0f} s.",
        "",
        f"* right names (multiplier >= {goal['strong_multiplier']:g} x noise, effect not "
        f"absorbed): **{_pct(s['correct_rate'])}** of {s['n_correct_rate_cases']} "
        f"(goal >= {_pct(goal['correct_rate_min'])}); first name right: "
        f"{_pct(s.get('first_name_correct_rate'))}",
        f"* absorbed by the geometry (after the geometric fit the residual passes the "
        f"chi-square test of pure noise, p >= {goal.get('absorbed_p', 0.01):g}; a rule on the "
        f"residual fixed in advance, not on the truth): {s.get('n_absorbed', 0)} strong cases, "
        "left out of the rate; " + absorbed_sentence(s),
        f"* false alarms on geometry-only truths: **{_pct(s['false_alarm_rate'])}** of "
        f"{s['n_none_cases']} (goal <= {_pct(goal['false_alarm_rate_max'])})",
        f"* audit (held-out) error worse after adding the named effect "
        f"(> {goal['worse_factor']:g} x before): **{s['heldout_worse_count']}** of "
        f"{s['n_audited']} audited (goal 0)",
        f"* goal met: **{'yes' if ok else 'no'}**",
        "",
        "## Per machine",
        "",
        "| machine | right names (strong, not absorbed) | cases | false alarms | none cases |",
        "|---|---|---|---|---|",
        *[
            f"| {m} | {_pct(v['correct_rate'])} | {v['n']} | "
            f"{_pct(s.get('false_alarm_rate_by_machine', {}).get(m, {}).get('false_alarm_rate'))}"
            f" | {s.get('false_alarm_rate_by_machine', {}).get(m, {}).get('n', 0)} |"
            for m, v in s.get("correct_rate_by_machine", {}).items()
        ],
        "",
        "## Confusion (true kind -> named)",
        "",
        *_figure(s, "confusion", "true effect x named effect, counts"),
        *confusion_table(s["confusion"]),
        "",
        "## Right names by magnitude (all kinds but none)",
        "",
        *_figure(s, "rate_by_size", "right names by effect size"),
        "| multiplier (x noise) | cases (not absorbed) | right | absorbed |",
        "|---|---|---|---|",
        *[
            f"| {m} | {v['n']} | {_pct(v['correct_rate'])} | {v.get('n_absorbed', 0)} |"
            for m, v in s["correct_rate_by_multiplier"].items()
        ],
        "",
        "## Right names by kind (multiplier >= strong)",
        "",
        "| kind | cases (not absorbed) | right | absorbed | accepted names |",
        "|---|---|---|---|---|",
        *[
            f"| {k} | {v['n']} | {_pct(v['correct_rate'])} | {v.get('n_absorbed', 0)} | "
            f"{', '.join(s['accepted_names'].get(k, []))} |"
            for k, v in s["correct_rate_by_kind"].items()
        ],
        "",
    ]
    if s.get("heldout_worse_cases"):
        lines += ["Audit error worse in:", ""]
        lines += [f"* {c}" for c in s["heldout_worse_cases"]]
        lines.append("")
    if s.get("not_audited"):
        lines += ["Not audited (the named correction exists only inside the diagnosis):", ""]
        lines += [f"* {c}" for c in s["not_audited"]]
        lines.append("")
    if s.get("skipped_cases"):
        lines += ["Cases skipped:", ""]
        lines += [f"* {c}" for c in s["skipped_cases"]]
        lines.append("")
    if s.get("skipped"):
        lines += ["Skipped kinds:", ""]
        lines += [f"* {c['machine']}: {c['kind']}: {c['reason']}" for c in s["skipped"]]
        lines.append("")
    lines += [
        "## Cases",
        "",
        "| machine | kind | x noise | seed | scaled argument | residual / noise | named | right "
        "| audit before -> after (mm, 3D RMS) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in s["cases"]:
        arg = (
            f"{c['scaled_argument']} = {c['argument_value']:.4g}" if "scaled_argument" in c else ""
        )
        after = c.get("audit_rms_after_mm")
        audit = (
            f"{c['audit_rms_before_mm']:.4f} -> {after:.4f}"
            if after is not None
            else f"{c.get('audit_rms_before_mm', float('nan')):.4f} -> n/a"
        )
        ratio = c.get("residual_over_noise")
        ratio_txt = (
            "" if ratio is None else f"{ratio:.2f}" + (" (absorbed)" if c.get("absorbed") else "")
        )
        lines.append(
            f"| {c['machine']} | {c['kind']} | {c['multiplier']:g} | {c['seed']} | {arg} | "
            f"{ratio_txt} | {c.get('named', c.get('skipped', ''))} | "
            f"{'yes' if c.get('correct') else 'no'} | {audit} |"
        )
    lines.append("")
    return "\n".join(lines)
