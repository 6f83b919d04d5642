"""What a verdict must say besides the residual: the cause a user must fix first, and how
little a fit identified.

* Readings in other units lead a failed verdict (:func:`units_first`): in the tracker's
  frame a registration and shrunken links follow readings in metres, and the failure itself
  would only name a consequence (estimates beyond a plausible size).
* A fit that identified less than half of the error model (one pose, a few poses in a small
  volume) is not a plain "ok" (:func:`little_identified`): the verdict says how many
  parameters the poses identified, how many equations they gave, how many degrees of freedom
  the residual has to judge the fit by, and how many poses give as many equations as
  parameters. The exit code stays 0: the fit is what the data allow, nothing to refuse.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from calib.data.hints import UNIT_SCALES
from calib.fit.verdict import Verdict


def units_first(verdict: Verdict) -> Verdict:
    """A failed verdict whose hints say the readings are in other units leads with that."""
    units = next((h for h in verdict.hints if h.startswith(tuple(UNIT_SCALES.values()))), None)
    if verdict.ok or units is None:
        return verdict
    rest = verdict.message.removeprefix("FAILED: ")
    return replace(verdict, message=f"FAILED: {units}; {rest}")


def little_identified(
    verdict: Verdict,
    n_identified: int,
    n_parameters: int,
    n_poses: int,
    n_targets: int,
    n_readings: int,
    n_registration: int = 0,
) -> Verdict:
    """An ok verdict on a fit that identified fewer than half of the ``n_parameters`` that
    the poses could have identified (parameters redundant with a registration left out)
    says so, with the numbers behind it. ``n_readings`` are the 3D readings kept."""
    if not verdict.ok or 2 * n_identified >= n_parameters:
        return verdict
    equations = 3 * n_readings
    dof = equations - n_identified - n_registration
    enough = math.ceil((n_parameters + n_registration) / (3 * n_targets))
    poses = "pose" if n_poses == 1 else "poses"
    return replace(
        verdict,
        message=(
            f"weak: only {n_identified} of {n_parameters} parameters identifiable from "
            f"{n_poses} {poses} ({equations} equations); the other "
            f"{n_parameters - n_identified} are kept at zero, each with its reason, "
            f"and the residual has {dof} degree(s) of freedom to judge the fit by; measure "
            f"more poses spread over the workspace (at least {enough} give as many equations "
            f"as unknowns). The fit: {verdict.message.removeprefix('ok: ')}"
        ),
    )


def with_notes(verdict: Verdict, result: Any, n_poses: int, n_targets: int) -> Verdict:
    """Both notes on the verdict of ``result`` (an IdentificationResult) over ``n_poses``
    poses of ``n_targets`` targets."""
    redundant = len(result.redundant_with_registration)
    return little_identified(
        units_first(verdict),
        int(result.report.n_identifiable),
        len(result.names) - redundant,
        n_poses,
        n_targets,
        n_poses * n_targets - len(result.rejected),
        0 if result.registration is None else 6,
    )
