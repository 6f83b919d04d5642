"""Applying a diagnosis's named effects to other poses (a test set, a compensation).

The library has two kinds of candidate, and each has its own way to act on new poses:

* actuator-level effects (gain, lead, eccentricity, backlash, drift, thermal growth of the
  screws, compliance) are offsets of the joint values: :func:`effect_offsets` gives them, to
  add to the commands before the forward kinematics (exact, not linearised);
* the others act on the readings directly: geometry beyond the error model (reflector
  offsets, joint-axis tilts), the structure's thermal expansion, the tracker's drift and
  scale. :func:`effect_target_shifts` gives their shift of every target (N, T, 3), linear in
  the coefficients about the geometric estimate, as the diagnosis fitted them.

Both take the ``Diagnosis.coefficients`` dict (name -> linear parameters, then the shape for
a shaped candidate) and the diagnosis's time axis (``time_origin``, ``time_unit``).
"""

from __future__ import annotations

import numpy as np

from calib.diagnosis.candidate import NO_SHAPE, Candidate
from calib.diagnosis.candidates import default_candidates, library
from calib.diagnosis.context import actuator_offsets, build_context
from calib.fit.identification import IdentificationResult
from calib.fit.model import CalibrationModel
from twin.kinematics.sensitivity import target_jacobian
from twin.kinematics.sensitivity_batch import target_jacobian_batch


def actuator_jacobians(model: CalibrationModel, values: np.ndarray, qpos: np.ndarray):
    """Per pose, d(targets)/d(actuator offsets), (N, T*3, A)."""
    mech = model.mechanism(values)
    offsets = actuator_offsets(model)
    zero = np.zeros(len(offsets))
    return np.array([target_jacobian(mech, offsets, zero, q) for q in qpos])


def actuator_jacobians_batch(model: CalibrationModel, values: np.ndarray, qpos: np.ndarray):
    """:func:`actuator_jacobians` by the batched adjoint (twin.kinematics.sensitivity_batch): the
    same
    derivatives to round-off (1e-12 relative, tested), all poses at once."""
    mech = model.mechanism(values)
    offsets = actuator_offsets(model)
    qpos = np.atleast_2d(np.asarray(qpos, dtype=float))
    jac = target_jacobian_batch(mech, offsets, np.zeros(len(offsets)), qpos)
    return jac.reshape(len(qpos), -1, len(offsets))


def kept_rows(result: IdentificationResult, shape: tuple[int, int]) -> np.ndarray:
    """(N, T*3) boolean: the residual rows of the readings ``result`` kept (not rejected)."""
    keep = np.ones(shape, dtype=bool)
    for rej in result.rejected:
        if rej.target_index < shape[1]:  # beyond: a probe's orientation (its point kept)
            keep[rej.pose_index, rej.target_index] = False
    return np.repeat(keep, 3, axis=1)


def _split(c: Candidate, coef) -> tuple[np.ndarray, float]:
    coef = np.asarray(coef, dtype=float)
    return (coef[:-1], float(coef[-1])) if c.shaped else (coef, NO_SHAPE)


def effect_offsets(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    chosen: dict[str, np.ndarray],
    candidates: list[Candidate] | None = None,
    time_origin: float = 0.0,
    time_unit: str = "pose",
) -> np.ndarray:
    """Actuator offsets (N, A) that the chosen effects predict for these commands (in
    measurement ``order``, or seconds for ``time_unit='s'``). Only actuator-level effects
    act here; the effects on the readings (geometry beyond the error model, thermal
    expansion, tracker drift and scale) are :func:`effect_target_shifts`' part."""
    mech = model.nominal
    lib = {
        c.name: c
        for c in candidates
        or default_candidates(mech.actuator_names, mech.actuator_is_slide, mech.masses_defaulted)
    }
    out = np.zeros_like(np.asarray(commands, dtype=float))
    acting = [n for n in chosen if n in lib and lib[n].offsets is not None]
    if not acting:
        return out
    need_gravity = any(n == "gravity_compliance" for n in acting)
    ctx = build_context(
        model,
        values,
        commands,
        np.asarray(order, dtype=float) - time_origin,
        time_unit,
        full=False,
        gravity=need_gravity,
    )
    for name in acting:
        theta, shape = _split(lib[name], chosen[name])
        out += np.einsum("nak,k->na", lib[name].offsets(ctx, shape), theta)
    return out


def effect_target_shifts(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    order: np.ndarray,
    chosen: dict[str, np.ndarray],
    time_origin: float = 0.0,
    time_unit: str = "pose",
    tracker_position_m: np.ndarray | None = None,
) -> np.ndarray:
    """Shift (N, T, 3) of every target that the chosen effects acting on the readings predict
    at these commands (geometry beyond the error model, thermal expansion, tracker drift and
    scale; ``tracker_position_m`` for the scale), linear about ``values``. Actuator-level
    effects contribute nothing here (see :func:`effect_offsets`); a name this machine's
    library does not hold raises KeyError."""
    mech = model.nominal
    commands = np.asarray(commands, dtype=float)
    n = len(commands)
    out = np.zeros((n, mech.n_targets * 3))
    names = list(chosen)
    if not names:
        return out.reshape(n, -1, 3)
    head = None if tracker_position_m is None else np.asarray(tracker_position_m, dtype=float)
    probe = {
        c.name: c
        for c in default_candidates(
            mech.actuator_names,
            mech.actuator_is_slide,
            mech.masses_defaulted,
            time_unit=time_unit,
            extra_groups={"reflector_offsets": (), "joint_axis_errors": ()},
            tracker_head=True,
        )
    }
    direct = [k for k in names if k in probe and probe[k].offsets is None]
    unknown = [k for k in names if k not in probe]
    if unknown:
        raise KeyError(f"effects not in this machine's library: {unknown}")
    if not direct:
        return out.reshape(n, -1, 3)
    pred = model.predict(values, commands)
    ctx = build_context(
        model,
        values,
        commands,
        np.asarray(order, dtype=float) - time_origin,
        time_unit,
        qpos=pred.qpos,
        targets=pred.targets,
        head=head,
        full=any(k in ("reflector_offsets", "joint_axis_errors") for k in direct),
        gravity=False,
    )
    lib = {c.name: c for c in library(ctx, mech.masses_defaulted)}
    for name in direct:
        if name == "tracker_scale" and head is None:
            raise ValueError("tracker_scale acts about the tracker head: give its position")
        theta, shape = _split(lib[name], chosen[name])
        out += lib[name].design(ctx, shape) @ theta
    return out.reshape(n, -1, 3)
