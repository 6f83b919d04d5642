"""One honest "before": the error the nominal commands leave, in one frame defined once.

A tracker-frame result carries its own registration, and how a fit splits a rigid motion
between that registration and the machine's weakly determined parameters is arbitrary: the
identified base frame is not the nominal one. Comparing the identified tool with the nominal
one in "the base frame" then measures that split (a Stewart platform's nominal commands were
said to leave 88.1 mm after one fit, 9.6 mm after another, for a measured 4.58 mm). The
tracker's frame is the one both models share: the identified tool goes there through the
identified registration, the nominal tool through the nominal model's registration on the
calibration set (calib.fit.nominal_registration), the frame verify's "before" uses too.
For a base-frame result both registrations are the identity and this is the base frame.
"""

from __future__ import annotations

import numpy as np

from calib.compensate.identified_machine import IdentifiedMachine
from calib.compensate.poses import tool_and_targets
from calib.fit.registration import Registration


def nominal_commands_error(
    machine: IdentifiedMachine,
    commands: np.ndarray,
    nominal_qpos: np.ndarray,
    nominal_registration: Registration | None,
) -> tuple[np.ndarray, np.ndarray]:
    """(tool (N,), reflectors (N,)): the 3D distance (SI) between where the identified
    machine puts the tool point, and the RMS over the reflectors of where it puts them, at
    the nominal ``commands`` (N, A), and where the nominal model puts them, both in the
    tracker's frame (the base frame for a base-frame result); NaN where a row cannot be
    evaluated. ``nominal_qpos`` (N, nq): the nominal configurations there (the branch).

    The reflectors' number is what the readings vouch for (verify's "before" on such
    poses); the tool point's is extrapolated from them and as well determined as the
    parameters that carry it (with one reflector, often not at all)."""
    joints = machine.joints_for_commands(commands)
    tool_i, targets_i = tool_and_targets(machine.mechanism, joints, nominal_qpos)
    tool_n, targets_n = tool_and_targets(machine.nominal, commands, nominal_qpos)
    if machine.registration is not None:
        if nominal_registration is None:
            nan = np.full(len(commands), np.nan)
            return nan, nan.copy()
        tool_i, targets_i = (machine.registration.to_tracker(v) for v in (tool_i, targets_i))
        tool_n, targets_n = (nominal_registration.to_tracker(v) for v in (tool_n, targets_n))
    tool = np.linalg.norm(tool_i - tool_n, axis=1)
    reflectors = np.sqrt(np.mean(np.sum((targets_i - targets_n) ** 2, axis=2), axis=1))
    return tool, reflectors
