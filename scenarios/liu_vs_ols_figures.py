"""Error maps of the liu_vs_ols scenario, one PNG per layer and quantity (like Figs. 6-9)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from scenarios.figures import plt, save_png


def _panel_map(
    path: Path, title: str, panels: list[tuple[str, np.ndarray, np.ndarray]], label: str
) -> None:
    vmax = max(float(np.max(v)) for _, _, v in panels)
    fig, axes = plt.subplots(
        1,
        len(panels),
        figsize=(3.2 * len(panels) + 1.2, 3.6),
        squeeze=False,
        constrained_layout=True,
    )
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
    save_png(fig, path)


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
                # the coarse stage on its own scale, the fine stages on one shared scale
                for part, chosen in (
                    ("coarse", [p for p in panels if p[0] == "coarse"]),
                    ("fine", [p for p in panels if p[0] != "coarse"]),
                ):
                    if not chosen:
                        continue
                    name = f"error_map_{tag}_{qty}_{part}.png"
                    _panel_map(
                        out_dir / name,
                        f"{group} layer z = {z * 1e3:+.0f} mm: {qty} after {part} calibration",
                        chosen,
                        label,
                    )
                    written[f"{tag}_{qty}_{part}"] = name
    return written
