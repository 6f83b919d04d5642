"""Figures of an identifiability analysis: the spectrum of the column-scaled H and what the
plan cannot see, by part of the machine. Sized for a view of about 550 x 500 pixels (one of
the recording's two figure views under the machine): about 5 x 4.6 inches at
scenarios.figures.DPI, text of 10-11 points."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.analysis import RANK_RTOL, scaled_jacobian
from scenarios.figures import plt, save_png
from scenarios.studies.polisher_identifiability.null_space import NullSpace

# what the plan sees of the parameters, in the order of the stacked bars, with their colours
CATEGORIES = {
    "alone": ("identified one by one", "#4c78a8"),
    "read": ("combinations read", "#9ecae9"),
    "unseen": ("directions unseen in them", "#f58518"),
    "no_effect": ("no effect on any target", "#e45756"),
}


def spectrum_png(path: Path, h: np.ndarray, title: str) -> tuple[Path, int]:
    """Singular values of the column-scaled H (log scale) with the rank threshold; returns
    the path and the numerical rank."""
    hs = scaled_jacobian(h)[0]
    s = np.linalg.svd(hs, compute_uv=False)
    rank = int(np.sum(s > RANK_RTOL * s[0]))
    fig, ax = plt.subplots(figsize=(5.2, 4.6))
    k = np.arange(1, len(s) + 1)
    ax.semilogy(k[:rank], s[:rank], "o", ms=4, label=f"kept ({rank})")
    zero = int(np.sum(s[rank:] < 1e-18))
    ax.semilogy(
        k[rank:],
        np.maximum(s[rank:], 1e-18),
        "x",
        ms=5,
        label=f"null ({len(s) - rank}; {zero} exactly 0,\ndrawn at 1e-18)",
    )
    ax.axhline(RANK_RTOL * s[0], color="grey", lw=1.0, ls="--", label="rank threshold")
    ax.set_xlabel("index", fontsize=11)
    ax.set_ylabel("singular value (column-scaled H)", fontsize=11)
    ax.tick_params(labelsize=10)
    ax.set_title(title, fontsize=11)
    ax.legend(fontsize=10, loc="upper right")
    fig.tight_layout()
    return save_png(fig, path), rank


def null_space_png(path: Path, seen: NullSpace, names: list[str]) -> Path:
    """Per part of the machine, a stacked bar of its parameters' dimensions: identified one by
    one, combinations the plan reads, directions unseen among those, and parameters with no
    effect on any target; the counts on the bars, the totals in the title."""
    rows = seen.rows(names)
    labels = list(rows)
    fig, ax = plt.subplots(figsize=(5.4, 2.4 + 0.5 * len(labels)), layout="constrained")
    y = np.arange(len(labels))
    left = np.zeros(len(labels))
    for key, (text, colour) in CATEGORIES.items():
        width = np.array([rows[r][key] for r in labels], dtype=float)
        total = int(width.sum())
        ax.barh(y, width, left=left, color=colour, label=f"{text} ({total})")
        for yi, (x0, w) in enumerate(zip(left, width, strict=True)):
            if w:
                ax.text(x0 + w / 2, yi, f"{w:.0f}", ha="center", va="center", fontsize=10)
        left += width
    ax.set_yticks(y, [_row_label(r) for r in labels], fontsize=10)
    ax.invert_yaxis()
    ax.set_xlabel("parameters (k mixed ones: read + unseen = k)", fontsize=10)
    ax.tick_params(axis="x", labelsize=10)
    unseen = sum(g.unseen for g in seen.mixed) + len(seen.no_effect)
    ax.set_title(
        f"what the plan cannot see: {unseen} of {len(names)} directions\n"
        f"(rank {seen.rank} = {len(seen.alone)} one by one"
        f" + {sum(g.read for g in seen.mixed)} combinations)",
        fontsize=11,
    )
    fig.legend(fontsize=10, loc="outside lower center", ncol=2, frameon=False)
    return save_png(fig, path)


def _row_label(row: str) -> str:
    """A part's name; a group spanning parts ("limb1 + limb2 + ...") as "across" them."""
    parts = row.split(" + ")
    return row if len(parts) == 1 else "across\n" + ",".join(parts)
