"""Which candidate poses the machine may be sent to and the tracker can measure.

A pose is feasible when (1) every actuator command lies inside its range shrunk by
``margin`` (a fraction of the range, on each side) and every limited passive joint inside
its range; (2) the nominal machine closes there (forward kinematics); (3) no geoms collide
and none reaches below the floor (calib.plan.collisions); (4) with a tracker position, every
reflector is in its line of sight within the acceptance angle (calib.plan.visibility).
The nominal model is what is checked: the errors being calibrated are millimetres, which the
margin is there to absorb."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import mujoco
import numpy as np

from calib.plan.collisions import CollisionChecker
from calib.plan.visibility import visibility_problem
from twin.exceptions import TwinError
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism

LIMITED = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


@dataclass(frozen=True)
class Rules:
    margin: float = 0.02  # fraction of each actuator's range kept free on each side
    floor_z_m: float | None = None  # base frame; None: the model's plane, if any
    tracker_m: np.ndarray | None = None  # (3,) base frame; None: no visibility check
    acceptance_deg: float = 30.0


@dataclass(frozen=True)
class Feasibility:
    ok: np.ndarray  # (C,) bool
    reasons: tuple[str | None, ...]  # why each pose is not feasible (None where it is)
    qpos: np.ndarray  # (C, nq) closed configurations (NaN where the machine does not close)
    floor_z_m: float | None

    def summary(self) -> str:
        """How many poses passed, and the most common reasons of the others."""
        kinds = Counter(r.split(":")[0] for r in self.reasons if r is not None)
        why = "; ".join(f"{n} {k}" for k, n in kinds.most_common())
        return f"{int(self.ok.sum())} of {len(self.ok)} candidate poses feasible" + (
            f" (left out: {why})" if why else ""
        )


def limit_problem(mech: Mechanism, commands: np.ndarray, margin: float) -> str | None:
    """Why a command row (A,) leaves its range shrunk by ``margin`` of it, or None."""
    lo, hi = mech.actuator_range[:, 0], mech.actuator_range[:, 1]
    pad = margin * (hi - lo)
    for k in np.flatnonzero((commands < lo + pad) | (commands > hi - pad)):
        scale, unit = (1e3, "mm") if mech.actuator_is_slide[k] else (np.degrees(1.0), "deg")
        return (
            f"limits: actuator '{mech.actuator_names[k]}' at {commands[k] * scale:.4g} {unit} "
            f"is within {margin:.0%} of its range's end [{lo[k] * scale:.4g}, "
            f"{hi[k] * scale:.4g}] {unit}"
        )
    return None


def passive_problem(mech: Mechanism, qpos: np.ndarray) -> str | None:
    """Why a closed configuration puts a limited joint outside its range, or None."""
    m = mech.model
    for j in range(m.njnt):
        if not m.jnt_limited[j] or int(m.jnt_type[j]) not in LIMITED:
            continue
        v, (lo, hi) = qpos[m.jnt_qposadr[j]], m.jnt_range[j]
        if v < lo - 1e-9 or v > hi + 1e-9:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or str(j)
            return f"limits: joint '{name}' leaves its range"
    return None


def closed_configurations(mech: Mechanism, commands: np.ndarray) -> np.ndarray:
    """Closed configurations (C, nq), NaN rows where forward kinematics fails."""
    try:
        return forward_batch(mech, commands, nthread=1, check_stroke=False).qpos
    except TwinError:
        out = np.full((len(commands), mech.model.nq), np.nan)
        for i, c in enumerate(commands):
            try:
                out[i] = forward_batch(mech, c[None], nthread=1, check_stroke=False).qpos[0]
            except TwinError:
                pass
        return out


def check_poses(mech: Mechanism, commands: np.ndarray, rules: Rules) -> Feasibility:
    """Each candidate's feasibility (module docstring), with the reason where it fails."""
    commands = np.atleast_2d(np.asarray(commands, dtype=float))
    qpos = closed_configurations(mech, commands)
    home = forward_batch(mech, mech.home_commands[None], nthread=1, check_stroke=False).qpos[0]
    checker = CollisionChecker.of(mech, home, rules.floor_z_m)
    tracker = None if rules.tracker_m is None else np.asarray(rules.tracker_m, dtype=float)
    reasons: list[str | None] = []
    for c, q in zip(commands, qpos, strict=True):
        why = limit_problem(mech, c, rules.margin)
        if why is None and not np.all(np.isfinite(q)):
            why = "closure: the machine does not close there"
        why = why or passive_problem(mech, q)
        if why is None:
            clash = checker.problem(q)  # leaves the kinematics of q in checker.data
            why = None if clash is None else f"collision: {clash}"
        if why is None and tracker is not None:
            seen = visibility_problem(
                mech, checker.model, checker.data, tracker, rules.acceptance_deg
            )
            why = None if seen is None else f"visibility: {seen}"
        reasons.append(why)
    ok = np.array([r is None for r in reasons])
    return Feasibility(ok, tuple(reasons), qpos, checker.floor_z)
