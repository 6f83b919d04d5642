"""ISO 9283 pose accuracy (AP) and pose repeatability (RP) of attained poses at commanded poses.

The standard's definitions (ISO 9283:1998, "Manipulating industrial robots: performance
criteria and related test methods"), for ``n`` attained poses ``(x_j, y_j, z_j, a_j, b_j,
c_j)`` reached from one command pose ``(x_c, y_c, z_c, a_c, b_c, c_c)``:

* barycentre ``x_bar = (1/n) sum x_j`` (likewise y, z; a, b, c);
* positional pose accuracy ``AP_P = sqrt((x_bar - x_c)^2 + (y_bar - y_c)^2 + (z_bar - z_c)^2)``
  with its parts ``AP_x = x_bar - x_c``, ``AP_y``, ``AP_z``;
* orientation pose accuracy ``AP_a = a_bar - a_c``, ``AP_b = b_bar - b_c``, ``AP_c = c_bar - c_c``;
* positional pose repeatability ``RP_l = l_bar + 3 S_l``, with ``l_j`` the distance of attained
  pose j from the barycentre, ``l_bar = (1/n) sum l_j`` and
  ``S_l = sqrt(sum (l_j - l_bar)^2 / (n - 1))``;
* orientation pose repeatability ``RP_a = +-3 S_a = +-3 sqrt(sum (a_j - a_bar)^2 / (n - 1))``
  (likewise b, c); the value given is the half-width 3 S_a.

``a, b, c`` are the rotations about the base x, y and z axes (roll, pitch, yaw:
``R = Rz(c) Ry(b) Rx(a)``). The angles of the attained poses are taken relative to the command
(wrapped to +-180 deg) before they are averaged, which equals the standard's differences
wherever no angle crosses +-180 deg, and stays right where one does.

Here the command pose of a side is what its model predicts for the command (the nominal
model: before; the calibrated model: after), its position the centroid of the pose's targets
and, with three or more targets, its orientation the rotation carrying the model's target
pattern onto them (a least-squares rigid fit); the attained pose is the same of the readings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.rigid_fit import fit_rigid_transform
from twin.rotations import rpy_from_matrix

STANDARD = "ISO 9283:1998 pose accuracy AP and pose repeatability RP"
POSITION_KEYS = ("AP_P_mm", "AP_x_mm", "AP_y_mm", "AP_z_mm", "RP_l_mm", "l_bar_mm", "S_l_mm")
ORIENTATION_KEYS = ("AP_a_deg", "AP_b_deg", "AP_c_deg", "RP_a_deg", "RP_b_deg", "RP_c_deg")


def _wrap_deg(angle: np.ndarray) -> np.ndarray:
    return (np.asarray(angle) + 180.0) % 360.0 - 180.0


def characteristics(
    attained_m: np.ndarray,
    command_m: np.ndarray,
    attained_rpy_deg: np.ndarray | None = None,
    command_rpy_deg: np.ndarray | None = None,
) -> dict[str, float]:
    """AP and RP of ``n`` attained positions (n, 3) metres at one command position (3,), and
    of their orientations (n, 3) roll-pitch-yaw degrees at the command's (3,) when given.

    Returns the standard's quantities in mm and deg (keys :data:`POSITION_KEYS`, and
    :data:`ORIENTATION_KEYS` with orientations), with ``n``."""
    x = np.asarray(attained_m, dtype=float).reshape(-1, 3) * 1e3
    c = np.asarray(command_m, dtype=float).reshape(3) * 1e3
    n = len(x)
    if n < 2:
        raise ValueError("ISO 9283 repeatability needs at least 2 attained poses per command")
    bary = x.mean(axis=0)
    ap = bary - c
    l_j = np.linalg.norm(x - bary, axis=1)
    l_bar = float(l_j.mean())
    s_l = float(np.sqrt(np.sum((l_j - l_bar) ** 2) / (n - 1)))
    out = {
        "n": n,
        "AP_P_mm": float(np.linalg.norm(ap)),
        "AP_x_mm": float(ap[0]),
        "AP_y_mm": float(ap[1]),
        "AP_z_mm": float(ap[2]),
        "RP_l_mm": l_bar + 3.0 * s_l,
        "l_bar_mm": l_bar,
        "S_l_mm": s_l,
    }
    if attained_rpy_deg is not None and command_rpy_deg is not None:
        rel = _wrap_deg(np.asarray(attained_rpy_deg, float) - np.asarray(command_rpy_deg, float))
        mean = rel.mean(axis=0)
        s = np.sqrt(np.sum((rel - mean) ** 2, axis=0) / (n - 1))
        for k, axis in enumerate("abc"):
            out[f"AP_{axis}_deg"] = float(mean[k])
            out[f"RP_{axis}_deg"] = float(3.0 * s[k])
    return out


def pose_of_targets(
    targets_m: np.ndarray, local_m: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """The position (..., 3) and roll-pitch-yaw in degrees (..., 3) of target sets (..., T, 3):
    their centroid and, with a pattern ``local_m`` (T, 3) of three or more targets, the
    rotation of the rigid fit of the pattern onto them (None otherwise)."""
    t = np.asarray(targets_m, dtype=float)
    position = t.mean(axis=-2)
    if local_m is None or t.shape[-2] < 3:
        return position, None
    flat = t.reshape(-1, t.shape[-2], 3)
    rpy = np.array([np.degrees(rpy_from_matrix(fit_rigid_transform(local_m, p)[0])) for p in flat])
    return position, rpy.reshape(*t.shape[:-2], 3)


def group_commands(commands: np.ndarray, decimals: int = 9) -> np.ndarray:
    """The commanded pose of each row (N, A) as a group index 0..G-1, in order of first
    appearance: rows with identical commands (SI, rounded to ``decimals``) share one."""
    keys = np.round(np.asarray(commands, dtype=float), decimals)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))  # renumber by first appearance
    return order[np.asarray(inverse).reshape(-1)]


@dataclass(frozen=True)
class IsoSide:
    """AP and RP per commanded pose for one side (before or after)."""

    per_pose: list[dict[str, float]]

    def worst(self, key: str) -> float:
        return float(max(abs(p[key]) for p in self.per_pose))


def iso_side(
    attained: np.ndarray,
    commanded: np.ndarray,
    groups: np.ndarray,
    local_m: np.ndarray | None,
) -> IsoSide:
    """AP and RP of attained target sets ``attained`` (N, T, 3) against ``commanded`` (N, T, 3),
    the rows grouped by commanded pose ``groups`` (N,) (the command's prediction is the same
    in every row of a group; the first is used)."""
    pos, rpy = pose_of_targets(attained, local_m)
    cpos, crpy = pose_of_targets(commanded, local_m)
    per_pose = []
    for g in range(int(groups.max()) + 1):
        rows = np.flatnonzero(groups == g)
        first = rows[0]
        per_pose.append(
            characteristics(
                pos[rows],
                cpos[first],
                None if rpy is None else rpy[rows],
                None if crpy is None else crpy[first],
            )
        )
    return IsoSide(per_pose)
