"""Figures of an identifiability analysis: the spectrum of the column-scaled H and what its
null space is made of."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.analysis import RANK_RTOL, scaled_jacobian
from scenarios.figures import plt, save_png


def spectrum_png(path: Path, h: np.ndarray, title: str) -> tuple[Path, int]:
    """Singular values of the column-scaled H (log scale) with the rank threshold; returns
    the path and the numerical rank."""
    hs = scaled_jacobian(h)[0]
    s = np.linalg.svd(hs, compute_uv=False)
    rank = int(np.sum(s > RANK_RTOL * s[0]))
    fig, ax = plt.subplots(figsize=(8, 3.6))
    k = np.arange(1, len(s) + 1)
    ax.semilogy(k[:rank], s[:rank], "o", ms=3, label=f"kept ({rank})")
    zero = int(np.sum(s[rank:] < 1e-18))
    ax.semilogy(
        k[rank:],
        np.maximum(s[rank:], 1e-18),
        "x",
        ms=4,
        label=f"null ({len(s) - rank}; {zero} exactly zero, drawn at 1e-18)",
    )
    ax.axhline(RANK_RTOL * s[0], color="grey", lw=0.8, ls="--", label="rank threshold")
    ax.set_xlabel("index")
    ax.set_ylabel("singular value of the column-scaled H")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_png(fig, path), rank


def null_space_png(
    path: Path, h: np.ndarray, names: list[str], title: str, top: int = 40
) -> tuple[Path, list[str]]:
    """How much of each parameter lies in the null space of the column-scaled H (the squared
    length of its row of the null-space basis: 1 = wholly unidentifiable, 0 = wholly fixed);
    the ``top`` largest as bars. Returns the path and the parameters above 0.5."""
    hs = scaled_jacobian(h)[0]
    _, s, vt = np.linalg.svd(hs, full_matrices=True)
    rank = int(np.sum(s > RANK_RTOL * s[0]))
    null = vt[rank:]
    share = np.sum(null**2, axis=0) if len(null) else np.zeros(hs.shape[1])
    order = np.argsort(-share)[:top]
    fig, ax = plt.subplots(figsize=(9, 0.18 * len(order) + 1.2))
    ax.barh(np.arange(len(order)), share[order], color="tab:red")
    ax.set_yticks(np.arange(len(order)), [names[i] for i in order], fontsize=6)
    ax.invert_yaxis()
    ax.set_xlim(0, 1)
    ax.set_xlabel("share in the null space (1: not identifiable at all)")
    ax.set_title(title)
    fig.tight_layout()
    return save_png(fig, path), [names[i] for i in np.flatnonzero(share > 0.5)]
