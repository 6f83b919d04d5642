"""Compensation with a result's residual correction (calib.correction): the commands that put
the identified machine's tool, the correction included, where asked.

The machine's tool point at commands c is the identified model's plus the correction there
(the mean of its reflectors' corrections: a translation; the orientation is not corrected).
The frames are solved again at the desired points less the correction at the last commands,
a fixed point that contracts as long as the correction changes less than the tool moves
(a smooth correction over the calibrated region: ``ROUNDS`` rounds). A pose outside the
calibrated region gets none and is listed.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calib.compensate.identified_machine import IdentifiedMachine
from calib.compensate.poses import (
    Compensation,
    SolvedPoses,
    _tool_at,
    compensate_frames,
    shown_residual,
)
from calib.correction import corrected_targets, correction_in

ROUNDS = 4


def _tool_shift(machine: IdentifiedMachine, corr, commands: np.ndarray):
    """The correction of the tool point (N, 3) at ``commands`` (0 where not reachable or
    outside), whether each pose is inside, and the predictive std (N,) m."""
    n = len(commands)
    shift, inside, std = np.zeros((n, 3)), np.zeros(n, bool), np.full(n, np.nan)
    ok = np.all(np.isfinite(commands), axis=1)
    if ok.any():
        pred = corrected_targets(corr, machine.model, machine.values, commands[ok])
        shift[ok] = pred["mean"].reshape(int(ok.sum()), -1, 3).mean(axis=1)
        inside[ok], std[ok] = pred["inside"], pred["std"]
    return shift, inside, std


def with_residual_correction(
    machine: IdentifiedMachine, comp: Compensation
) -> tuple[Compensation, list[str], dict | None]:
    """``comp`` solved again with the result's residual correction (unchanged without one),
    the lines to print and the sidecar's ``residual_correction`` entry."""
    corr = correction_in(machine.result.data, machine.model, str(machine.result.path))
    if corr is None:
        return comp, [], None
    first, desired = comp, comp.positions
    nominal = SolvedPoses(comp.nominal_commands, comp.nominal_qpos, comp.problems)
    shift, inside, _ = _tool_shift(machine, corr, comp.commands)
    lost = np.zeros(len(desired), bool)
    for _ in range(ROUNDS):
        new = compensate_frames(
            machine, comp.pose_ids, comp.rotations, desired - shift, nominal, skip=first.problems
        )
        lost |= first.reachable & ~new.reachable
        comp = _merge(first, new, lost)
        shift, inside, std = _tool_shift(machine, corr, comp.commands)
        shift[lost], inside[lost] = 0.0, False
    joints = machine.joints_for_commands(comp.commands)
    _, pos = _tool_at(machine.mechanism, joints, comp.nominal_qpos)
    residual = np.linalg.norm(pos + shift - desired, axis=1)
    comp = replace(
        comp,
        positions=desired,
        residual_m=residual,
        nominal_error_m=first.nominal_error_m,
        nominal_reflector_error_m=first.nominal_reflector_error_m,
    )
    outside = [
        str(p)
        for p, i, r, k in zip(comp.pose_ids, inside, comp.reachable, lost, strict=True)
        if r and not i and not k
    ]
    missed = [str(p) for p, k in zip(comp.pose_ids, lost, strict=True) if k]
    lines = [
        f"residual correction applied at {int((inside & comp.reachable).sum())} of "
        f"{int(comp.reachable.sum())} reachable poses (predictive std median "
        f"{np.nanmedian(std[inside]) * 1e3 if inside.any() else 0.0:.4f} mm per coordinate); "
        f"{len(outside)} outside the calibrated region, uncorrected"
        + (f": pose_id {', '.join(outside[:20])}" if outside else ""),
        (
            f"{len(missed)} pose(s) the solve with the correction did not reach, written "
            f"uncorrected: pose_id {', '.join(missed)}"
            if missed
            else None
        ),
        "predicted residual at the written commands with the correction: max "
        f"{shown_residual(float(np.nanmax(residual, initial=0.0)) * 1e3, 'mm')} at the tool point",
    ]
    entry = {
        "applied": [str(p) for p, i in zip(comp.pose_ids, inside, strict=True) if i],
        "outside_calibrated_region": outside,
        "not_reached_with_correction": missed,
        "std_mm_per_coordinate": [None if np.isnan(s) else float(s * 1e3) for s in std],
        "tool_point_correction_mm": (shift * 1e3).tolist(),
    }
    return comp, lines, entry


def _merge(first: Compensation, comp: Compensation, lost: np.ndarray) -> Compensation:
    """``comp`` with the first solve's rows where ``lost`` (the solve with the correction
    failed where the first did not)."""
    if not lost.any():
        return comp
    problems = tuple(
        f if k else c for f, c, k in zip(first.problems, comp.problems, lost, strict=True)
    )
    return replace(
        comp,
        commands=np.where(lost[:, None], first.commands, comp.commands),
        problems=problems,
        residual_m=np.where(lost, first.residual_m, comp.residual_m),
        residual_rad=np.where(lost, first.residual_rad, comp.residual_rad),
    )
