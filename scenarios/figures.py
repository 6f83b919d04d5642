"""PNG figures for reports (matplotlib, Agg), each written atomically."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def save_png(fig, path: Path) -> Path:
    """Write ``fig`` to ``path`` through a temporary file in the same folder, then close it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".png")
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110)
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def parameter_bars_png(
    path: Path,
    title: str,
    names: Sequence[str],
    estimates: np.ndarray,
    std: np.ndarray | None = None,
    truth: np.ndarray | None = None,
    unit_label: str = "mm / deg",
) -> Path:
    """Horizontal bars of estimates with +-2 std error bars and truth markers."""
    n = len(names)
    fig, ax = plt.subplots(figsize=(7.5, 1.2 + 0.18 * n))
    y = np.arange(n)
    err = None if std is None else 2.0 * np.nan_to_num(np.asarray(std))
    ax.barh(
        y,
        estimates,
        xerr=err,
        color="#4c78a8",
        ecolor="#333333",
        capsize=2,
        label="estimate (+-2 std)",
    )
    if truth is not None:
        ax.plot(truth, y, "o", color="#e45756", markersize=3, label="truth")
    ax.set_yticks(y, names, fontsize=6)
    ax.invert_yaxis()
    ax.axvline(0.0, color="#999999", linewidth=0.6)
    ax.set_xlabel(unit_label)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return save_png(fig, path)


def index_vs_count_png(
    path: Path,
    title: str,
    counts: Sequence[int],
    series: dict[str, Sequence[float]],
    ylabel: str,
    log_y: bool = True,
) -> Path:
    """An observability index against the number of poses, one line per series."""
    fig, ax = plt.subplots(figsize=(6.5, 4.0))
    for label, values in series.items():
        ax.plot(counts[: len(values)], values, marker=".", label=label)
    if log_y:
        ax.set_yscale("log")
    ax.set_xlabel("number of poses")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return save_png(fig, path)
