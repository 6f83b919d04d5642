"""Does the residual follow where or when a pose was measured? Rank correlations, in words.

The size of each pose's residual is rank-correlated (Spearman) with every pose variable: the
tool position's coordinates, each actuator command, and the measurement order. A variable
is named when its correlation is significant after a Bonferroni correction over all of them;
none named means no such monotone structure, not that there is none (``pkm-calib diagnose``
tests the shapes it knows and a kernel correction for the rest).
"""

from __future__ import annotations

import numpy as np

from calib.analysis.spearman import spearman

ALPHA = 0.01


def rank_correlations(size: np.ndarray, probes: dict[str, np.ndarray]) -> dict[str, dict]:
    """Spearman rho and p of ``size`` (N,) with each probe (N,); rho 0, p 1 where either
    is constant."""
    size = np.asarray(size, dtype=float)
    out = {}
    for name, v in probes.items():
        v = np.asarray(v, dtype=float)
        if np.ptp(v) > 0 and np.ptp(size) > 0 and len(v) > 2:
            rho, p = spearman(size, v)
            out[name] = {"rho": float(np.nan_to_num(rho)), "p": float(np.nan_to_num(p, nan=1.0))}
        else:
            out[name] = {"rho": 0.0, "p": 1.0}
    return out


def pose_probes(
    commands: np.ndarray,
    actuator_names: tuple[str, ...],
    tool_position: np.ndarray,
    order: np.ndarray,
) -> dict[str, np.ndarray]:
    """The pose variables a residual is tested against: tool x, y, z, each actuator, order."""
    probes = {f"tool {c}": np.asarray(tool_position)[:, i] for i, c in enumerate("xyz")}
    for i, n in enumerate(actuator_names):
        probes[n] = np.asarray(commands)[:, i]
    probes["measurement order"] = np.asarray(order, dtype=float)
    return probes


def significant(correlations: dict[str, dict], alpha: float = ALPHA) -> list[tuple[str, float]]:
    """(name, rho) of the significant correlations (Bonferroni), strongest first."""
    level = alpha / max(len(correlations), 1)
    hits = [(n, c["rho"]) for n, c in correlations.items() if c["p"] < level]
    return sorted(hits, key=lambda h: -abs(h[1]))


def describe(correlations: dict[str, dict], alpha: float = ALPHA) -> str:
    """One clause: what the residual's size follows, or that no rank test finds structure."""
    hits = significant(correlations, alpha)
    if not hits:
        return (
            "its size follows no pose variable or the measurement order monotonically "
            f"(Spearman, {len(correlations)} variables tested)"
        )
    shown = ", ".join(f"{n} (rho {r:+.2f})" for n, r in hits[:4])
    return f"it is structured: its size follows {shown}"
