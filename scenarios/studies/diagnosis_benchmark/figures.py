"""The diagnosis benchmark's figures: the confusion matrix as a heat map (true effect x named
effect, counts) and the rate of right names by effect size (multiples of the tracker noise).

The confusion matrix names its rows and columns alike, so that its diagonal holds the right
names: each class is the set of diagnosis names :data:`ACCEPTED` counts as right for a twin
kind ("none" aside where others are right too), named by its first name; a row is the class
of the case's true kind, a column the class of the name the diagnosis gave (a name
``is_correct`` accepts: the row's class). Names that belong to no class (a kernel's
"unexplained: ...", two effects of different classes, a refused case) get columns of their
own after the square part.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from scenarios.figures import plt, save_png
from scenarios.studies.diagnosis_benchmark.kinds import ACCEPTED, is_correct

CONFUSION = "confusion.png"
RATE = "rate_by_size.png"


def kind_class(kind: str) -> tuple[str, ...]:
    """The diagnosis names right for twin ``kind`` ("none" only where nothing else is)."""
    names = tuple(n for n in ACCEPTED[kind] if n != "none")
    return names or ("none",)


def classes() -> list[tuple[str, ...]]:
    """Every kind's class, in :data:`ACCEPTED`'s order, "none" last."""
    out = list(dict.fromkeys(kind_class(k) for k in ACCEPTED))
    return [c for c in out if c != ("none",)] + [("none",)]


def name_class(named: str) -> tuple[str, ...] | str:
    """The class every effect of ``named`` ("a+b": two) belongs to, or the column of its
    own: "unexplained", "refused", "several effects", or the name itself."""
    for prefix in ("unexplained", "refused"):
        if named.startswith(prefix):
            return prefix
    found = {c for p in named.split("+") for c in classes() if p in c}
    if len(found) == 1 and all(any(p in c for c in found) for p in named.split("+")):
        return found.pop()
    return "several effects" if "+" in named else named


def class_label(c: tuple[str, ...]) -> str:
    """A class by its first name; "(+k alike)" when it holds more."""
    return c[0] if len(c) == 1 else f"{c[0]} (+{len(c) - 1} alike)"


def confusion_matrix(
    confusion: dict[str, dict[str, int]],
) -> tuple[list[str], list[str], np.ndarray, list[str]]:
    """(row labels, column labels, counts (rows, columns), notes): the first len(rows)
    columns are the rows' classes in the rows' order, so the diagonal is the right names;
    notes name the classes of more than one name."""
    cells: dict[tuple[Any, Any], int] = {}
    for kind, row in confusion.items():
        for named, count in row.items():
            column = kind_class(kind) if is_correct(kind, named) else name_class(named)
            key = (kind_class(kind), column)
            cells[key] = cells.get(key, 0) + int(count)
    used = {k for k, _ in cells} | {c for _, c in cells if isinstance(c, tuple)}
    square = [c for c in classes() if c in used]
    extra = sorted({c for _, c in cells if isinstance(c, str)})
    columns: list[Any] = [*square, *extra]
    counts = np.zeros((len(square), len(columns)))
    for (r, c), n in cells.items():
        counts[square.index(r), columns.index(c)] += n
    notes = [f"{class_label(c)}: {', '.join(c)}" for c in square if len(c) > 1]
    labels = [class_label(c) for c in square]
    return labels, labels + extra, counts, notes


def confusion_png(path: Path, confusion: dict[str, dict[str, int]]) -> Path:
    """The counts of :func:`confusion_matrix`, annotated; the right names on the diagonal."""
    rows, columns, counts, notes = confusion_matrix(confusion)
    n = len(rows)
    right = int(np.trace(counts[:, :n])) if n else 0
    fig, ax = plt.subplots(
        # landscape, about the shape of the recording's view (two side by side over the report)
        figsize=(3.4 + 0.62 * len(columns), 2.4 + 0.26 * n + 0.2 * len(notes)),
        layout="constrained",
    )
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
                fontsize=10,
                color="k" if c > 0.6 * top else "w",
                fontweight="bold" if i == j else "normal",
            )
    if len(columns) > n:  # the names of no class, apart
        ax.axvline(n - 0.5, color="w", lw=3)
    ax.set_xticks(np.arange(len(columns)), columns, rotation=30, ha="right", fontsize=10)
    ax.set_yticks(np.arange(n), rows, fontsize=10)
    ax.set_xlabel("\n".join(["named by the diagnosis", *notes]), fontsize=10)
    ax.set_ylabel("effect in the truth", fontsize=10)
    ax.set_title(
        f"right names on the diagonal: {right} of {int(counts.sum())} cases\n"
        "(every size, absorbed cases included)",
        fontsize=11,
    )
    bar = fig.colorbar(im, ax=ax, shrink=0.8)
    bar.set_label("cases", fontsize=10)
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
    for i, (m, xi, r) in enumerate(zip(sizes, x, rate, strict=True)):
        n, a = by_multiplier[m]["n"], by_multiplier[m]["n_absorbed"]
        note = f"{n} cases" + (f", {a} absorbed" if a else "")
        # below the point where the line rises to the next one, so that it does not cross the
        # text; the end points' text kept inside the axes
        below = i + 1 < len(rate) and bool(rate[i + 1] > r)
        ax.annotate(
            note,
            (xi, 100 * (0 if np.isnan(r) else r)),
            xytext=(0, -8 if below else 6),
            textcoords="offset points",
            ha="left" if i == 0 else "right" if i == len(rate) - 1 else "center",
            va="top" if below else "bottom",
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
