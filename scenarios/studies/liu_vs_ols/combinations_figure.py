"""The estimates figure of liu_vs_ols: each kept parameter's estimate beside the truth as the
plan reads it (left), and the combinations the readings fix and those they cannot (right,
grey), with the sentence that says why (``combinations.sentence``)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from scenarios.figures import DPI, plt, save_png
from scenarios.studies.liu_vs_ols.combinations import Combinations

ESTIMATE, TRUTH, UNREADABLE = "#4c78a8", "#e45756", "#dddddd"
LINEAR_WITHIN = 0.01  # mm or deg: the symmetric-log axes are linear within +-this


def _panel(
    ax: plt.Axes,
    labels: list[str],
    estimate: np.ndarray,
    std: np.ndarray,
    truth: np.ndarray,
    grey: np.ndarray,
) -> None:
    y = np.arange(len(labels))
    for k in np.flatnonzero(grey):
        ax.axhspan(k - 0.5, k + 0.5, color=UNREADABLE, zorder=0)
    ax.errorbar(
        estimate,
        y,
        xerr=2.0 * std,
        fmt="o",
        color=ESTIMATE,
        ecolor=ESTIMATE,
        markersize=3,
        capsize=2,
        linewidth=0.8,
        label="estimate ± 2 std",
    )
    ax.plot(truth, y, "D", color=TRUTH, markersize=3.5, label="truth as the plan reads it")
    ax.axvline(0.0, color="#999999", linewidth=0.6)
    ax.set_xscale("symlog", linthresh=LINEAR_WITHIN)
    ax.set_yticks(y, labels, fontsize=6)
    ax.set_ylim(len(labels) - 0.5, -0.5)
    ax.grid(axis="x", alpha=0.3)
    ax.set_xlabel(f"mm or deg (symmetric log: linear within ±{LINEAR_WITHIN:g})", fontsize=8)
    ax.tick_params(axis="x", labelsize=7)


def combinations_png(
    path: Path,
    label: str,
    c: Combinations,
    estimate: np.ndarray,
    std: np.ndarray,
    truth: np.ndarray,
    text: str,
) -> Path:
    """Left: the kept parameters (``estimate``, ``std``, ``truth`` in mm and deg, by
    ``c.names``), members of an unreadable combination on grey; right: ``c``'s combinations,
    the unreadable ones on grey; ``text`` under both."""
    n = len(c.names)
    wrapped = "\n".join(textwrap.wrap(text, 190))
    below = 0.75 + 0.14 * (wrapped.count("\n") + 1)  # inches: the x label and the text
    width, height = 15.0, 0.6 + below + 0.17 * n
    fig = plt.figure(figsize=(width, height), dpi=DPI)
    # fixed margins in inches: the names' column of each panel (parameters, combinations)
    bottom, top = below / height, 1 - 0.55 / height
    left = fig.add_axes((1.5 / width, bottom, 4.6 / width, top - bottom))
    right = fig.add_axes((10.1 / width, bottom, 4.75 / width, top - bottom))
    members = set(c.unreadable_members())
    grey = np.array([name in members for name in c.names])
    _panel(left, list(c.names), estimate, std, truth, grey)
    left.set_title(
        f"{label}: the {n} kept parameters\n(grey: members of a combination not readable)",
        fontsize=9,
    )
    combos = [f"{i + 1}: {c.label(i)}" for i in range(n)]
    _panel(right, combos, c.estimate, c.std, c.truth, ~c.readable)
    right.set_title(
        f"what the readings fix: {int(np.sum(c.readable))} of {n} combinations, smallest "
        f"standard error first\n(grey: ±2 std wider than the ±{c.bound:g} the errors were "
        "drawn in: not readable)",
        fontsize=9,
    )
    handles, names = right.get_legend_handles_labels()
    fig.legend(handles, names, fontsize=7, loc="upper left", ncols=2, frameon=False)
    fig.text(0.01, 0.1 / height, wrapped, fontsize=7.5, va="bottom", ha="left")
    return save_png(fig, path)
