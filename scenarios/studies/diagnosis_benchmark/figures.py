"""The diagnosis benchmark's figures: the confusion matrix as a heat map (true effect x named
effect, counts) and the rate of right names by effect size (multiples of the tracker noise)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from scenarios.figures import plt, save_png

CONFUSION = "confusion.png"
RATE = "rate_by_size.png"


def confusion_png(path: Path, confusion: dict[str, dict[str, int]]) -> Path:
    """Counts of each named effect (columns) for each true kind (rows), annotated."""
    kinds = sorted(confusion)
    named = sorted({n for row in confusion.values() for n in row})
    counts = np.array([[confusion[k].get(n, 0) for n in named] for k in kinds], dtype=float)
    fig, ax = plt.subplots(figsize=(1.6 + 0.55 * len(named), 1.4 + 0.38 * len(kinds)))
    im = ax.imshow(counts, cmap="viridis", aspect="auto")
    top = counts.max() if counts.size else 0.0
    for (i, j), c in np.ndenumerate(counts):
        if c:
            ax.text(
                j,
                i,
                f"{c:.0f}",
                ha="center",
                va="center",
                fontsize=7,
                color="k" if c > 0.6 * top else "w",
            )
    ax.set_xticks(np.arange(len(named)), named, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(np.arange(len(kinds)), kinds, fontsize=7)
    ax.set_xlabel("named by the diagnosis")
    ax.set_ylabel("effect in the truth")
    ax.set_title("diagnosis benchmark: cases by true and named effect", fontsize=9)
    fig.colorbar(im, ax=ax, label="cases", shrink=0.8)
    fig.tight_layout()
    return save_png(fig, path)


def rate_png(path: Path, by_multiplier: dict[str, dict[str, Any]], strong: float) -> Path:
    """The share of right names against the effect's size, with the cases counted."""
    sizes = sorted(by_multiplier, key=float)
    x = np.array([float(m) for m in sizes])
    rate = np.array(
        [
            np.nan if by_multiplier[m]["correct_rate"] is None else by_multiplier[m]["correct_rate"]
            for m in sizes
        ]
    )
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.plot(x, 100 * rate, "o-", color="#4c78a8")
    for m, xi, r in zip(sizes, x, rate, strict=True):
        n, a = by_multiplier[m]["n"], by_multiplier[m]["n_absorbed"]
        note = f"{n} cases" + (f", {a} absorbed" if a else "")
        ax.annotate(
            note,
            (xi, 100 * (0 if np.isnan(r) else r)),
            xytext=(0, 6),
            textcoords="offset points",
            ha="center",
            fontsize=7,
        )
    ax.axvline(strong, color="k", lw=0.8, ls="--", label=f"{strong:g} x noise: the goal's cases")
    ax.set_xscale("log")
    ax.set_xticks(x, [f"{v:g}" for v in x])
    ax.set_ylim(0, 110)
    ax.set_xlabel("effect size (multiples of the tracker noise, log)")
    ax.set_ylabel("right names (%, absorbed cases left out)")
    ax.set_title("diagnosis benchmark: right names by effect size", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return save_png(fig, path)


def write_figures(out_dir: Path, summary: dict[str, Any], strong: float) -> dict[str, str]:
    out: dict[str, str] = {}
    if summary.get("confusion"):
        confusion_png(out_dir / CONFUSION, summary["confusion"])
        out["confusion"] = CONFUSION
    if summary.get("correct_rate_by_multiplier"):
        rate_png(out_dir / RATE, summary["correct_rate_by_multiplier"], strong)
        out["rate_by_size"] = RATE
    return out
