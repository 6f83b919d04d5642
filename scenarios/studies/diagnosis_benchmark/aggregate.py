"""The diagnosis benchmark's aggregate: confusion, rates of the goal, absorbed cases."""

from __future__ import annotations

from typing import Any

WORSE_FACTOR = 1.02  # audit RMS after > before * this: the named effect made it worse
STRONG_MULTIPLIER = 2.0  # correct_rate counts the cases at or above this many noise sigmas
# The rule, fixed before any run, for an effect the geometry absorbs: after the geometric fit
# the residual passes the chi-square test of pure tracker noise (p >= ABSORBED_P, the level
# at which the diagnosis itself calls a residual an excess). It is computed from the residual
# of the geometric fit only, never from the truth label or the magnitude: the effect has then
# left nothing in the data to detect, "none" is no error of the diagnosis, and the case is
# counted as "absorbed" beside correct_rate, not in it.
ABSORBED_P = 0.01


def aggregate(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The confusion table and the rates of the benchmark's goal."""
    done = [r for r in results if "named" in r]
    confusion: dict[str, dict[str, int]] = {}
    for r in done:
        row = confusion.setdefault(r["kind"], {})
        row[r["named"]] = row.get(r["named"], 0) + 1
    effect = [r for r in done if r["kind"] != "none" and r["multiplier"] >= STRONG_MULTIPLIER]
    strong = [r for r in effect if not r.get("absorbed")]
    absorbed = [r for r in effect if r.get("absorbed")]
    nones = [r for r in done if r["kind"] == "none"]
    audited = [r for r in done if r.get("audit_rms_after_mm") is not None]
    worse = [
        r for r in audited if r["audit_rms_after_mm"] > r["audit_rms_before_mm"] * WORSE_FACTOR
    ]
    by_mult: dict[str, dict[str, float]] = {}
    for mult in sorted({r["multiplier"] for r in done if r["kind"] != "none"}):
        rs = [r for r in done if r["kind"] != "none" and r["multiplier"] == mult]
        seen = [r for r in rs if not r.get("absorbed")]
        by_mult[f"{mult:g}"] = {
            "n": len(seen),
            "correct_rate": _rate(seen, "correct"),
            "n_absorbed": len(rs) - len(seen),
        }
    by_kind = {
        k: {
            "n": len(rs),
            "correct_rate": _rate(rs, "correct"),
            "n_absorbed": sum(r["kind"] == k for r in absorbed),
        }
        for k in sorted({r["kind"] for r in effect})
        for rs in [[r for r in strong if r["kind"] == k]]
    }
    return {
        "n_cases": len(done),
        "confusion": confusion,
        "correct_rate": _rate(strong, "correct"),
        # the first (strongest) name right, whatever else was named beside it
        "first_name_correct_rate": _rate(strong, "first_correct"),
        "n_correct_rate_cases": len(strong),
        # strong cases whose effect the geometric fit absorbed (ABSORBED_P), not in the rate
        "n_absorbed": len(absorbed),
        "absorbed_cases": [
            {
                k: r[k]
                for k in ("machine", "kind", "multiplier", "seed", "named", "residual_over_noise")
            }
            for r in absorbed
        ],
        # the rate if the absorbed cases counted as misses (for comparison only)
        "correct_rate_with_absorbed": _rate(effect, "correct"),
        "correct_rate_by_machine": {
            m: {"n": len(rs), "correct_rate": _rate(rs, "correct")}
            for m in sorted({r["machine"] for r in effect})
            for rs in [[r for r in strong if r["machine"] == m]]
        },
        "false_alarm_rate_by_machine": {
            m: {"n": len(rs), "false_alarm_rate": _rate_named(rs)}
            for m in sorted({r["machine"] for r in nones})
            for rs in [[r for r in nones if r["machine"] == m]]
        },
        "false_alarm_rate": _rate_named(nones),
        "n_none_cases": len(nones),
        "heldout_worse_count": len(worse),
        "skipped_cases": [
            {k: r[k] for k in ("machine", "kind", "multiplier", "seed", "skipped")}
            for r in results
            if "named" not in r
        ],
        "n_audited": len(audited),
        "not_audited": [
            {k: r[k] for k in ("machine", "kind", "multiplier", "seed", "named")}
            for r in done
            if r.get("audit_rms_after_mm") is None
        ],
        "heldout_worse_cases": [
            {k: r[k] for k in ("machine", "kind", "multiplier", "seed", "named")} for r in worse
        ],
        "correct_rate_by_multiplier": by_mult,
        # in-process time of the cases (s), per machine: what a run costs on one core
        "case_runtime_s_by_machine": {
            m: round(sum(r.get("runtime_s", 0.0) for r in results if r["machine"] == m), 1)
            for m in sorted({r["machine"] for r in results})
        },
        "correct_rate_by_kind": by_kind,
    }


def _rate(rs: list[dict[str, Any]], key: str) -> float | None:
    return sum(bool(r[key]) for r in rs) / len(rs) if rs else None


def _rate_named(rs: list[dict[str, Any]]) -> float | None:
    """The share of cases in which anything but "none" was named."""
    return sum(r["named"] != "none" for r in rs) / len(rs) if rs else None
