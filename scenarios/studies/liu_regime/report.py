"""report.md of the regime map: where each estimator beats OLS, cell by cell, in words made
from the numbers."""

from __future__ import annotations

from typing import Any

from scenarios.studies.liu_vs_ols.report import shown, truth_text
from scenarios.studies.liu_vs_ols.sentences import (
    CONTROL_LIMIT_UM,
    PAPER_CELL,
    effects_phrase,
    paper_relative_gain,
)

CLEAR = 0.9  # "wins clearly": better in at least this fraction of the draws


SIGN = (
    "estimator minus OLS (below 0: the estimator is better; um in the tables and sentences, "
    "mm in the heat maps, as in every figure)"
)


def _best(s: dict[str, Any]) -> tuple[str, str, float, float] | None:
    """(cell, estimator, median minus OLS um, better fraction) of the lowest median."""
    best = None
    for cell, c in s["cells"].items():
        for label, e in c["estimators"].items():
            diff = e["minus_ols_um"]["median"]
            if best is None or diff < best[2]:
                best = (cell, label, diff, e["better_fraction"])
    return best


def _in_max(e: dict[str, Any]) -> str:
    """The same estimator in the test maximum, when the summary has it."""
    m = e.get("minus_ols_max_um")
    if not m:
        return ""
    better = e.get("better_fraction_max")
    return f"; in the test maximum {m['median']:+.3g} um" + (
        "" if better is None else f" (better in {better:.0%})"
    )


def noise_free_sentence(s: dict[str, Any]) -> str | None:
    """The cells at sigma 0, when the map has them: with no noise to take off, whatever an
    estimator changes there is the estimate's bias moved, not noise removed."""
    free = {c: v for c, v in s["cells"].items() if c.rsplit("/", 1)[-1] == "0"}
    if not free:
        return None
    parts = [
        f"`{shown(label)}` in {cell.rsplit('/', 1)[0]} {e['minus_ols_um']['median']:+.3g} um "
        f"({e['better_fraction']:.0%} better)"
        for cell, v in free.items()
        for label, e in v["estimators"].items()
    ]
    moved = any(
        e["minus_ols_um"]["median"] != 0.0 for v in free.values() for e in v["estimators"].values()
    )
    return (
        "Noise-free (sigma 0), where shrinkage has no noise to take off, estimator minus OLS "
        f"in the test mean (median): {'; '.join(parts)}"
        + (
            ": what shrinkage changes there is the bias of the estimate, moved, not noise."
            if moved
            else ": nothing moves without noise."
        )
    )


def verdict_sentences(s: dict[str, Any]) -> list[str]:
    out = []
    paper = s["cells"].get(PAPER_CELL, {}).get("estimators", {}).get("liu_paper_deg")
    if paper:
        diff = paper["minus_ols_um"]["median"]
        out.append(
            f"In the paper's cell ({PAPER_CELL}) the paper's estimator minus OLS in the test "
            f"mean is {diff:+.3g} um (median; better in {paper['better_fraction']:.0%} "
            f"of draws){_in_max(paper)}."
        )
    for label in s["estimators"]:
        wins = [
            cell
            for cell, c in s["cells"].items()
            if c["estimators"][label]["better_fraction"] >= CLEAR
            and c["estimators"][label]["minus_ols_um"]["median"] < 0
        ]
        out.append(
            f"`{shown(label)}` beats OLS in the test mean in at least {CLEAR:.0%} of the draws "
            "in "
            + (
                f"{len(wins)} of {len(s['cells'])} cells: {', '.join(wins)}."
                if wins
                else "no cell."
            )
        )
    best = _best(s)
    if best is not None and best[2] < 0:
        ols = s["cells"][best[0]]["ols_test_pos_mean_um"]["median"]
        e = s["cells"][best[0]]["estimators"][best[1]]
        out.append(
            f"The lowest median is {best[2]:+.3g} um ({-best[2] / ols:.1%} of OLS's "
            f"{ols:.3g} um there), by `{shown(best[1])}` in {best[0]} (better in "
            f"{best[3]:.0%} of draws){_in_max(e)}."
        )
    elif best is not None:
        out.append("No estimator has a median below OLS's test mean in any cell.")
    free = noise_free_sentence(s)
    if free:
        out.append(free)
    return out


def _spread_text(m: dict[str, float]) -> str:
    return f"{m['median']:+.3g} ({m['p05']:+.3g}..{m['p95']:+.3g})"


def _cell_table(s: dict[str, Any]) -> list[str]:
    labels = s["estimators"]
    heads = []
    for lab in labels:
        heads += [f"{shown(lab)}: mean, better", f"{shown(lab)}: max, better"]
    lines = [
        "Each estimator minus OLS, median (p05..p95) um over the draws, in the test mean and "
        "in the test maximum, and the share of draws it is better (below 0):",
        "",
        "| cell | OLS test mean (um) | OLS test max (um) | " + " | ".join(heads) + " |",
        "|---|---|---|" + "---|" * len(heads),
    ]
    for cell, c in s["cells"].items():
        ols_max = c.get("ols_test_pos_max_um")
        row = [
            cell,
            f"{c['ols_test_pos_mean_um']['median']:.3g}",
            "n/a" if ols_max is None else f"{ols_max['median']:.3g}",
        ]
        for lab in labels:
            e = c["estimators"][lab]
            row.append(f"{_spread_text(e['minus_ols_um'])}, {e['better_fraction']:.0%}")
            m, better = e.get("minus_ols_max_um"), e.get("better_fraction_max")
            row.append(
                "n/a"
                if m is None
                else _spread_text(m) + ("" if better is None else f", {better:.0%}")
            )
        lines.append("| " + " | ".join(row) + " |")
    return lines


def _parameters(s: dict[str, Any]) -> list[str]:
    rows = []
    for sigma, block in s.get("estimator_parameters", {}).items():
        for label, v in block.items():
            rows.append(
                f"| {sigma} | {shown(label)} | {v['d_median']:.3g} | {v['k_median']:.3g} | "
                f"{v['d_over_k_median']:.3g} |"
            )
    if not rows:
        return []
    return [
        "How much each Liu variant chose to shrink (medians over the draws; d/k = 1 is OLS, "
        "0 is ridge with the same k):",
        "",
        "| sigma (mm) | estimator | d | k | d/k |",
        "|---|---|---|---|---|",
        *rows,
        "",
    ]


def report(s: dict[str, Any]) -> str:
    effects = s.get("truth_effects") or []
    control = s["scoring"]["order_control_um"]
    lines = [
        "# Hybrid polisher: where Liu beats OLS (the regime map)",
        "",
        f"liu_vs_ols's plan and twin: source errors {truth_text(s.get('truth_random'))}; "
        + (
            f"effects {', '.join(effects)} ({effects_phrase(effects)})"
            if effects
            else "no effect beyond geometry"
        )
        + f". {s['n_draws']} truth draws per cell (seeds {s['seeds'][0]}..{s['seeds'][1]}, the "
        "same truths and noise normals at every sigma), engine "
        f"{s['engine']}, runtime {s['runtime_s']:.0f} s. Each cell: the estimator's test mean "
        "position error minus OLS's, um (below 0: better than OLS), and the fraction of draws "
        "in which it is better; the test maximum likewise (the paper's Liu: "
        f"{paper_relative_gain('pos_mean_mm'):+.1%} in the mean, "
        f"{paper_relative_gain('pos_max_mm'):+.1%} in the maximum). One sign everywhere, "
        "tables, sentences and heat maps: " + SIGN + ". "
        "`liu_paper_deg` is the paper's Liu (Eq. 11 with k = 1 on H in "
        "mm and deg, Eq. 14's d, sigma^2 = RSS / n); `liu` is the Liu-type estimator with the "
        "Hoerl-Kennard-Baldwin k on the column-scaled H.",
        "",
        "Test placements:",
        "",
        *[
            f"* {p}: {v['description']}, {v['n_poses']} poses"
            for p, v in s["placement_poses"].items()
        ],
        "",
        f"Every stage of a draw was scored from the same clock; the 'OLS again' control differs "
        f"from OLS by at most {control:.3g} um in any draw of any cell"
        + (": within round-off." if control < CONTROL_LIMIT_UM else ": NOT within round-off."),
        "",
        "## What the map says",
        "",
        *[f"* {line}" for line in verdict_sentences(s)],
        "",
        "## The cells",
        "",
        *_cell_table(s),
        "",
        *_parameters(s),
    ]
    figs = s.get("figures") or {}
    if figs:
        lines += [
            "## Heat maps (colour and text: median estimator minus OLS in the test mean, mm; "
            "% of draws better)",
            "",
        ]
        lines += [f"![{name}]({path})" for name, path in figs.items()]
        lines.append("")
    return "\n".join(lines)
