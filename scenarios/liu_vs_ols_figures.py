"""Error maps of the liu_vs_ols scenario, one PNG per layer and quantity (like Figs. 6-9)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def _save(fig, path: Path) -> None:
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


def _panel_map(
    path: Path, title: str, panels: list[tuple[str, np.ndarray, np.ndarray]], label: str
) -> None:
    vmax = max(float(np.max(v)) for _, _, v in panels)
    fig, axes = plt.subplots(1, len(panels), figsize=(3.6 * len(panels), 3.6), squeeze=False)
    for ax, (name, xy, values) in zip(axes[0], panels, strict=True):
        sc = ax.scatter(xy[:, 0], xy[:, 1], c=values, cmap="viridis", vmin=0, vmax=vmax, s=60)
        k = int(np.argmax(values))
        ax.annotate(
            f"max {values[k]:.3f}", xy[k], textcoords="offset points", xytext=(4, 4), fontsize=7
        )
        ax.set_title(f"{name}\nmax {values.max():.3f}, mean {values.mean():.3f}", fontsize=9)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_aspect("equal")
    fig.colorbar(sc, ax=axes[0].tolist(), label=label, shrink=0.85)
    fig.suptitle(title, fontsize=10)
    _save(fig, path)


def write_figures(out_dir: Path, maps: dict[str, dict[str, Any]]) -> dict[str, str]:
    """maps[group][stage] = (poses (N, 6), PoseErrors); one PNG per layer height and quantity."""
    written: dict[str, str] = {}
    for group, stages in maps.items():
        first_poses = next(iter(stages.values()))[0]
        for z in np.unique(np.round(first_poses[:, 2], 9)):
            panels_pos, panels_ori = [], []
            for stage, (poses, errs) in stages.items():
                sel = np.isclose(poses[:, 2], z)
                xy = poses[sel, :2] * 1e3
                panels_pos.append((stage, xy, errs.position[sel] * 1e3))
                panels_ori.append((stage, xy, np.degrees(errs.orientation[sel])))
            tag = f"{group}_z{z * 1e3:+.0f}mm"
            for qty, panels, label in (
                ("position", panels_pos, "position error (mm)"),
                ("orientation", panels_ori, "orientation error (deg)"),
            ):
                name = f"error_map_{tag}_{qty}.png"
                _panel_map(
                    out_dir / name, f"{group} layer z = {z * 1e3:+.0f} mm: {qty}", panels, label
                )
                written[f"{tag}_{qty}"] = name
    return written
