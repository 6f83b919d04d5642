"""How far the tool turns per millimetre its tool point moves, for each source error.

An effect that acts through one joint or one link of the machine (backlash, a transmission or
encoder error, compliance, thermal growth or lead error of a limb) displaces the tool by that
source error's twist: the tool point moves by ``v`` and the tool turns by ``w``. The ratio
``|w| / |v|`` is fixed by the geometry alone: a rotation about an axis at distance ``r`` from the
tool point gives ``1 / r`` radians per metre. Computed from the controller's model (nominal
geometry, no truth), it says how much orientation error such an effect can leave beside a
given position error, and so whether a measured pair of position and orientation errors can
come from effects of the machine at all. The papers' tables give both errors per stage; their
ratio is compared with this reach in the liu_vs_ols report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# below this tool-point motion per unit source error (m per SI unit) a source error's ratio is
# not computed: it only turns the tool (or does nothing) at that pose
MIN_MOTION = 1e-9


@dataclass(frozen=True)
class ReachRow:
    name: str
    joint_motion: bool  # an error along the joint's own motion (encoder kind)
    median_deg_per_mm: float  # over the poses
    max_deg_per_mm: float


@dataclass(frozen=True)
class OrientationReach:
    rows: list[ReachRow]  # every source error that moves the tool, largest median first

    def largest(self, joint_motion_only: bool = False) -> ReachRow:
        rows = [r for r in self.rows if r.joint_motion or not joint_motion_only]
        if not rows:
            raise ValueError("no source error of this kind moves the tool")
        return rows[0]

    def as_dict(self) -> dict:
        big, joint = self.largest(), self.largest(joint_motion_only=True)
        return {
            "largest_median_deg_per_mm": big.median_deg_per_mm,
            "largest_source_error": big.name,
            "largest_joint_motion_median_deg_per_mm": joint.median_deg_per_mm,
            "largest_joint_motion": joint.name,
            "joint_motions": {
                r.name: {
                    "median_deg_per_mm": r.median_deg_per_mm,
                    "max_deg_per_mm": r.max_deg_per_mm,
                }
                for r in self.rows
                if r.joint_motion
            },
        }


def deg_per_mm(rotation_rad: np.ndarray, translation_m: np.ndarray) -> np.ndarray:
    """Orientation over position error in the report's units, degrees per millimetre."""
    return np.degrees(rotation_rad) / (np.asarray(translation_m) * 1e3)


def orientation_reach(
    twists: np.ndarray, names: list[str], joint_motion: np.ndarray
) -> OrientationReach:
    """Per source error, the tool's rotation per tool-point motion over the poses.

    ``twists``: (N, 6, n) tool twist Jacobians (tool-point velocity, then angular velocity) at
    N poses; ``joint_motion``: (n,) True for the errors along a joint's own motion."""
    twists = np.asarray(twists, dtype=float)
    if twists.ndim != 3 or twists.shape[1] != 6 or twists.shape[2] != len(names):
        raise ValueError(f"twists must be (N, 6, {len(names)}), got {twists.shape}")
    lin = np.linalg.norm(twists[:, :3], axis=1)
    ang = np.linalg.norm(twists[:, 3:], axis=1)
    rows = []
    for j, name in enumerate(names):
        moved = lin[:, j] > MIN_MOTION
        if not moved.any():
            continue
        ratio = deg_per_mm(ang[moved, j], lin[moved, j])
        rows.append(
            ReachRow(name, bool(joint_motion[j]), float(np.median(ratio)), float(ratio.max()))
        )
    rows.sort(key=lambda r: (-r.median_deg_per_mm, r.name))
    return OrientationReach(rows)
