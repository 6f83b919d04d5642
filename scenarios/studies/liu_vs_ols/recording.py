"""What liu_vs_ols logs to its recording: the polisher at the test nodes with each stage's
pose error (coarse, OLS, Liu and the loop, one view each), the
loop's own view (the residual against the variable that explains the effect the diagnosis
named), the error maps, the coarse rounds and the parameter tables."""

from __future__ import annotations

import tempfile
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.recording.recorder import Recorder
from scenarios.recording.targets import field_scale
from twin.kinematics import forward_batch
from twin.workspace import commands_for_poses

MACHINE_STAGES = ("coarse", "ols", "liu", "loop")
TIMELINE = "test_node"


def record(
    recorder: Recorder,
    nominal: Any,
    maps: dict[str, dict[str, Any]],
    estimates: dict[str, tuple[Any, np.ndarray]],
    kept_names: list[str],
    shown: np.ndarray,
    coarse_changes: list[float],
    loop: Any,
) -> None:
    if not recorder.enabled:
        return
    recorder.log_mechanism(nominal)
    test = maps.get("test", {})
    stages = [s for s in MACHINE_STAGES if s in test]
    if stages:
        poses = test[stages[0]][0]
        qpos = forward_batch(nominal, commands_for_poses(nominal, poses)).qpos
        tool = poses[:, :3]
        # the tool point's error as scored (effects and all) at every node of the layer at
        # once, magnified to be seen in each stage's view (the factor in its title, the size
        # in mm on the label of the node the machine stands at)
        for stage in stages:
            error = test[stage][1].position_vectors
            recorder.log_poses(
                TIMELINE,
                range(len(poses)),
                nominal,
                qpos,
                tool[:, None],
                (tool + error)[:, None],
                f"{stage}, test layer",
                scale=field_scale(tool, tool + error),
                field=True,
            )
    for group, by_stage in maps.items():
        for stage, (p, errs) in by_stage.items():
            vmax = float(np.max(errs.position)) * 1e3  # each stage on its own colour scale
            recorder.log_error_map(stage, group, p[:, :3], errs.position * 1e3, vmax)
    for label, (est, _) in estimates.items():
        recorder.log_parameters(label, kept_names, est.x * shown, est.std_errors * shown)
    recorder.log_figure("loop", loop_png(loop), f"loop: {loop.verdict()[0]}")
    recorder.log_figure("coarse_rounds", coarse_png(coarse_changes), "coarse rounds")


def loop_png(loop: Any) -> bytes:
    """The diagnosis figure of the loop (calib.diagnosis.figure), as bytes."""
    from calib.diagnosis import save_diagnosis_png
    from scenarios.figures import plt, png_bytes

    diag = loop.diagnosis
    if diag.plot is None:  # nothing named: say so in a figure of its own, wrapped to fit it
        chosen, reason = loop.verdict()
        lines = [f"loop: {chosen}", *textwrap.wrap(reason, 70)]
        fig, ax = plt.subplots(figsize=(7, 0.6 + 0.3 * len(lines)))
        ax.axis("off")
        ax.text(0.5, 0.5, "\n".join(lines), ha="center", va="center", fontsize=11)
        return png_bytes(fig)
    with tempfile.TemporaryDirectory() as tmp:
        path = save_diagnosis_png(diag, Path(tmp) / "loop.png")
        return path.read_bytes()


def coarse_png(changes: list[float]) -> bytes:
    """The relative change of the encoder offsets in each coarse round (log axis)."""
    from scenarios.figures import plt, png_bytes

    fig, ax = plt.subplots(figsize=(5, 3))
    rounds = np.arange(1, len(changes) + 1)
    ax.bar(rounds, np.maximum(np.asarray(changes, dtype=float), 1e-300), color="#4c78a8")
    ax.set_yscale("log")
    ax.set_xticks(rounds, [f"round {k}" for k in rounds])
    ax.set_ylabel("relative change of the estimate (log)")
    ax.set_title("coarse calibration: change in each round", fontsize=9)
    fig.tight_layout()
    return png_bytes(fig)
