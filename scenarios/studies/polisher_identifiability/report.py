"""report.md of the polisher_identifiability scenario."""

from __future__ import annotations

from typing import Any


def report(s: dict[str, Any]) -> str:
    paper = s["paper_table2_per_limb"]
    ours = s["identifiable_per_limb"]
    lines = [
        "# Hybrid polisher: source errors and their identifiability",
        "",
        f"Plan: {s['n_poses']} poses (pure translation, layers x nodes as in the scenario file),"
        f" {s['n_equations']} equations from three gauge targets.",
        "",
        "| quantity | ours | paper |",
        "|---|---|---|",
        f"| source errors (Appendix A) | {s['n_source_errors']} | {s['paper_source_errors']} |",
        f"| identifiable (Steps 1-3, H_xi first) | {s['n_identifiable']} | {paper['total']} |",
        f"| rank by spectral decomposition | {s['rank_spectral']} | |",
        f"| rank by pivoted QR | {s['rank_pivoted_qr']} | |",
    ]
    for limb, n in ours.items():
        lines.append(f"| of which {limb} | {n} | {paper.get(limb, '')} |")
    lines += [
        f"| limbs 2 and 3 alike | {s['limbs_2_and_3_alike']} | yes |",
        f"| condition number (scaled, Steps 1-3 set) | {s['condition_number']:.4g} | |",
        "",
        "## The spectrum and the null space",
        "",
        f"![singular values of the column-scaled H]({s['figures']['singular_values']})",
        "",
        f"Rank {s['rank_of_figure']} of {s['n_source_errors']}. Source errors mostly (share "
        f"> 0.5; a pair's members, exactly one half each, not counted) in the null space: "
        f"{len(s['mostly_in_null_space'])}.",
        "",
        f"![what the plan cannot see, by part of the machine]({s['figures']['null_space']})",
        "",
        *([groups_markdown(s["null_space"])] if "null_space" in s else []),
        "",
        "## Cross-checks",
        "",
        f"* screw-theory H against the twin's implicit-function H: max relative difference "
        f"{s['screw_vs_twin_max_rel_err']:.2e};",
        f"* twin H against finite differences of the full nonlinear forward kinematics: "
        f"{s['jacobian_fd_max_rel_err']:.2e}.",
        "",
        "## Why the counts differ from the paper",
        "",
        "* Source errors: Appendix A's rule (6 for each limb's base frame, 5 for every 1-DOF",
        "  joint frame, one offset per actuated joint) gives 4 x 6 + (3 x 6 + 6) x 5 + 6 = 150",
        "  for three UPS limbs (U, P, S = 6 joints), the UP limb (3 joints) and the wrist (3).",
        "  The paper states 145 without listing them; 5 fewer would mean one joint frame",
        "  fewer, which its text does not say.",
        "* Identifiable: a UPS limb acts on the platform only through its actuation wrench, a",
        "  force along the limb; errors whose twist is reciprocal to that force (rotations",
        "  about axes through A1,i or A6,i, translations normal to the limb) have no effect",
        f"  ({len(s['no_effect'])} such columns here). What remains per limb depends on how the",
        "  U and S joints' axes are laid out, which the paper's missing Fig. 2 shows and its",
        "  text does not: with the S joint's first axis along the limb, its internal offsets",
        "  only lengthen the limb and 44 combinations are identifiable; with it normal to the",
        "  limb (our model), 51. The paper's Table 2 also lists dz_3,i for the P joint,",
        "  which Appendix A excludes (the P joint's own axis), so its frames are numbered",
        "  differently from its appendix. Both our H agree to round-off, so the count is a",
        "  property of the model, not of the computation.",
        "",
        "## Which layer plan (pure translation)",
        "",
        "| layers (mm) | nodes | poses | identifiable | cond. of the paper plan's set | "
        "OLS overall std, 0.005 mm noise (mm, deg) |",
        "|---|---|---|---|---|---|",
        *[
            f"| {p['layer_heights_mm']} | {p['nodes_per_side']} x {p['nodes_per_side']} | "
            f"{p['n_poses']} | {p['n_identifiable']} | "
            + (
                f"{p['condition_number_of_paper_set']:.4g}"
                if p["condition_number_of_paper_set"]
                else "not all identifiable"
            )
            + f" | {p['ols_overall_std_for_0.005mm_noise']:.4g} |"
            for p in s.get("plans", [])
        ],
        "",
        "The condition number does not reward more measurements (it is a ratio); the overall",
        "standard deviation of the OLS estimates (Eq. 18) does, and it is what a user pays for",
        "in measuring time: read the two columns together.",
        "",
        "## Identifiable set (Steps 1-3)",
        "",
        ", ".join(s["identifiable"]),
        "",
    ]
    return "\n".join(lines)


def null_space_sentence(n: dict[str, Any]) -> str:
    """Why the plan cannot see what it cannot, in the counts of ``n`` (summary's null_space)."""
    mixed = sum(len(g["members"]) for g in n["groups"])
    return (
        f"Of the {n['alone'] + mixed + n['no_effect']} source errors, {n['no_effect']} move no "
        f"target at any pose of the plan (their columns of H are zero), and {mixed} fall in "
        f"{len(n['groups'])} groups whose columns of H are linearly dependent: what one of "
        f"them does to every reading, a combination of the others does too, so the plan reads "
        f"only {n['read_in_combinations']} combinations of them and "
        f"{n['unseen_in_combinations']} directions stay unseen. The rank, {n['rank']}, is the "
        f"{n['alone']} errors identified one by one plus those "
        f"{n['read_in_combinations']} combinations."
    )


def groups_markdown(n: dict[str, Any]) -> str:
    """The sentence of :func:`null_space_sentence` and the mixed groups, one bullet each (a
    list wraps in a narrow view, where a table's row of 23 names runs off it)."""
    rows = [
        f"* {len(g['members'])} read as {g['read']}, {g['unseen']} unseen: "
        + ", ".join(g["members"])
        for g in n["groups"]
    ]
    return "\n".join(
        [
            null_space_sentence(n),
            "",
            "Source errors read only together (count read as combinations, directions unseen):",
            "",
            *rows,
        ]
    )
