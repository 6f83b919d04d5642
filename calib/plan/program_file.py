"""The program as a CSV in the units of datasets (mm for prismatic, deg for revolute actuators):

    pose_id,set,cmd:<actuator 1>,...,cmd:<actuator A>,dir:<actuator 1>,...,dir:<actuator A>

one row per pose in the order to run them; ``set`` is calibration or test; ``dir:<actuator>``
is the side from which the actuator should reach its command (+1 moving up, -1 moving down:
calib.plan.ordering). The commands of ``compensate --commands`` and of a Dataset are the
same columns; ``pose_id`` is the candidate's own (its pose_id in a candidates file)."""

from __future__ import annotations

import io

import numpy as np

from calib.plan.planner import Plan
from twin.mechanism import Mechanism


def file_units(mech: Mechanism, commands: np.ndarray) -> np.ndarray:
    """Commands (N, A) from SI to mm (prismatic) and deg (revolute)."""
    return np.where(mech.actuator_is_slide, 1e3, 180.0 / np.pi) * np.asarray(commands)


def program_text(mech: Mechanism, plan: Plan) -> str:
    names = mech.actuator_names
    head = ["pose_id", "set", *(f"cmd:{a}" for a in names), *(f"dir:{a}" for a in names)]
    buf = io.StringIO()
    buf.write(",".join(head) + "\n")
    shown = file_units(mech, plan.commands)
    for label, set_name, row, dirs in zip(
        plan.labels, plan.sets, shown, plan.order.directions, strict=True
    ):
        cells = [label, str(set_name), *(f"{v:.10g}" for v in row), *(f"{int(d):+d}" for d in dirs)]
        buf.write(",".join(cells) + "\n")
    return buf.getvalue()
