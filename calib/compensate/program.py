"""A robot's program compensated: its joint targets, corrected so the machine does what they meant.

A program is what a controller runs: joint targets (actuator commands). What each target
means is where the NOMINAL model puts the tool at it, position and orientation of the tool
frame (the programmer's or the offline planner's model). The corrected target is the
commands that put the IDENTIFIED machine's tool frame there, solved by Newton from the
program's own configuration (so the arm keeps its branch: shoulder, elbow and wrist flips
are never crossed), then turned into commands through the identified actuator gains and
joint compliances (calib.compensate.poses.compensate_frames). A target whose own commands
are past a stroke, or at which the nominal model does not close, is named, not solved.

The same nominal configurations seed position-only desired poses (``compensate --poses``
with ``--commands`` or ``--seed``): the orientation and the branch of a seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.compensate.identified_machine import IdentifiedMachine
from calib.compensate.poses import Compensation, SolvedPoses, compensate_frames, stroke_excess
from twin.exceptions import ClosureError, WorkspaceError
from twin.kinematics.single_pose import forward
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class NominalTargets:
    """Where the nominal model puts the tool at given commands (NaN rows: a problem)."""

    commands: np.ndarray  # (N, A) SI, as given
    qpos: np.ndarray  # (N, nq) the nominal model's closed configuration there
    rotations: np.ndarray  # (N, 3, 3) tool frame, base frame
    positions: np.ndarray  # (N, 3) tool point, base frame, SI
    problems: tuple[str | None, ...]

    @property
    def solved(self) -> SolvedPoses:
        """The targets as the nominal solution of their own tool frames."""
        ok = np.array([p is None for p in self.problems])
        return SolvedPoses(np.where(ok[:, None], self.commands, np.nan), self.qpos, self.problems)


def nominal_targets(mech: Mechanism, commands: np.ndarray) -> NominalTargets:
    """The nominal tool frames at ``commands`` (N, A) (SI); a target past a stroke or at
    which the closures do not solve is named with the reason."""
    commands = np.atleast_2d(np.asarray(commands, dtype=float))
    n = len(commands)
    qpos = np.full((n, mech.model.nq), np.nan)
    rot = np.full((n, 3, 3), np.nan)
    pos = np.full((n, 3), np.nan)
    problems: list[str | None] = []
    for i, c in enumerate(commands):
        excess = stroke_excess(mech, c)
        if excess:
            problems.append(f"the program's own command: {excess}")
            continue
        try:
            sol = forward(mech, c, check_stroke=False)
        except (ClosureError, WorkspaceError) as exc:
            problems.append(f"the nominal model does not close at the program's commands ({exc})")
            continue
        qpos[i], rot[i], pos[i] = sol.qpos, sol.tool_rotation, sol.tool_position
        problems.append(None)
    return NominalTargets(commands, qpos, rot, pos, tuple(problems))


def compensate_program(
    machine: IdentifiedMachine, commands: np.ndarray, pose_ids: tuple[str, ...]
) -> Compensation:
    """Corrected commands (N, A) for the program's ``commands`` (N, A) (SI): each puts the
    identified tool frame where the nominal model puts it at the program's commands, solved
    from the program's configuration; the nominal commands are the program's own."""
    targets = nominal_targets(machine.nominal, commands)
    return compensate_frames(
        machine,
        pose_ids,
        targets.rotations,
        targets.positions,
        targets.solved,
        skip=targets.problems,
    )


def nearest_targets(targets: NominalTargets, positions: np.ndarray) -> np.ndarray:
    """For each position (N, 3) (base frame), the index of the program target whose nominal
    tool point is nearest (targets with a problem never chosen); -1 when none is usable."""
    ok = np.array([p is None for p in targets.problems])
    if not ok.any():
        return np.full(len(positions), -1)
    d = np.linalg.norm(positions[:, None, :] - targets.positions[None, :, :], axis=2)
    d[:, ~ok] = np.inf
    return np.argmin(d, axis=1)
