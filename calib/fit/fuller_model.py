"""The error model's fuller variant, tried before readings are rejected as gross outliers.

An error model too small for the machine leaves a residual with structure, and the readings
where that structure is largest can pass the outlier rule (calib.fit.robust) although
nothing is wrong with them. For readings in the machine's base frame nothing absorbs the
placement of the machine's base in the world (for tracker-frame readings the registration
does): an error model without it, such as a DH table's generated with ``--no-base-errors``,
is the common case.

* :func:`base_placement` gives the six placement errors of the machine's root body (the one
  body the world holds; every other body beneath it): ``body_pos`` along and ``body_rot``
  about the world's x, y, z, named ``<root>.dx .. <root>.rz`` as the DH generator names
  them, when the error model cannot already move the machine rigidly (some rigid motion of
  the reflectors lies outside the span of its Jacobian's columns at the estimate).
* :func:`explained` compares the readings a fit rejects with those the fuller fit rejects by
  the same rule; the fuller model is kept (calib.fit.workflow) when it keeps some readings
  the smaller one rejected and rejects no more in all, and :class:`FullerModel` says why.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from calib.exceptions import CalibError
from calib.fit.model import CalibrationModel
from calib.fit.registration import rigid_motion_span
from calib.fit.robust import Rejection, RobustOptions
from twin.exceptions import TwinError
from twin.parameters import Parameter, ParameterSet

if TYPE_CHECKING:
    from calib.data.dataset import Dataset
    from calib.fit.identification import IdentificationResult
    from calib.fit.observations import Observations

AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
# a rigid motion counts as held by the error model when its part outside the span of the
# model's (column-normalised) Jacobian is below this fraction of its norm: exact spans give
# round-off (1e-12 here), a missing direction a residual of order one
SPANNED = 1e-6


def _root_body(model: CalibrationModel) -> int | None:
    """The one body the world holds, if the machine has exactly one."""
    m = model.nominal.model
    roots = [b for b in range(1, m.nbody) if int(m.body_parentid[b]) == 0]
    return roots[0] if len(roots) == 1 else None


def holds_rigid_motion(model: CalibrationModel, values: np.ndarray, commands: np.ndarray) -> bool:
    """Whether the error model's parameters can move every reflector as one rigid motion of
    the machine (to first order at ``values``, over ``commands``)."""
    pred = model.predict(values, commands)
    jac = np.asarray(model.jacobian(values, pred), dtype=float)
    span = rigid_motion_span(pred.targets)
    norms = np.linalg.norm(jac, axis=0)
    cols = jac[:, norms > 0] / norms[norms > 0]
    if cols.shape[1] == 0:
        return False
    u, s, _ = np.linalg.svd(cols, full_matrices=False)
    u = u[:, s > s[0] * 1e-10]
    outside = span - u @ (u.T @ span)
    rel = np.linalg.norm(outside, axis=0) / np.maximum(np.linalg.norm(span, axis=0), 1e-300)
    return bool(np.all(rel < SPANNED))


def base_placement(
    model: CalibrationModel, values: np.ndarray, commands: np.ndarray
) -> list[Parameter]:
    """The placement errors of the root body the error model lacks (none when it already
    moves the machine rigidly, or the machine has no single root body)."""
    root = _root_body(model)
    if root is None or holds_rigid_motion(model, values, commands):
        return []
    m = model.nominal.model
    body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, root) or ""
    if not body:
        return []
    have = {(p.kind, p.element, tuple(map(float, p.axis))) for p in model.params.parameters}
    names = set(model.params.names)
    out = []
    for kind, letter in (("body_pos", "d"), ("body_rot", "r")):
        for c, axis in AXES.items():
            if (kind, body, axis) in have:
                continue
            name = f"{body}.{letter}{c}"
            name = name if name not in names else f"{body}.placement_{letter}{c}"
            out.append(Parameter(name, kind, body, axis))
    return out


def with_parameters(model: CalibrationModel, added: list[Parameter]) -> CalibrationModel:
    """``model`` with ``added`` appended to its error model."""
    params = ParameterSet([*model.params.parameters, *added], model.nominal.model)
    return CalibrationModel(model.nominal, params)


def rejection_limit_m(robust_scale_m: float, opt: RobustOptions | None = None) -> float:
    """The outlier rule's limit on a reading's 3D residual at a fit's robust scale."""
    opt = opt or RobustOptions()
    scale = robust_scale_m if np.isfinite(robust_scale_m) else 0.0
    return max(opt.threshold * scale, opt.floor_m)


def explained(
    before: tuple[Rejection, ...], after: tuple[Rejection, ...]
) -> tuple[Rejection, ...] | None:
    """The readings of ``before`` the fuller fit keeps, if the fuller model is to be kept:
    it keeps some of them and rejects no more readings in all; else None."""
    kept_now = {(r.pose_index, r.target_index) for r in after}
    out = tuple(r for r in before if (r.pose_index, r.target_index) not in kept_now)
    return out if out and len(after) < len(before) else None


@dataclass(frozen=True)
class FullerModel:
    """Why the fit carries parameters beyond the error model's file."""

    added: tuple[Parameter, ...]
    what: str  # the added parameters in words
    explained: tuple[dict, ...]  # the readings kept: pose_id, target, residual_mm (smaller fit)
    rejected_before: int  # readings the smaller model's fit rejected
    limit_before_mm: float  # its outlier limit
    rejected_after: int  # readings the fuller fit rejects
    limit_after_mm: float  # its outlier limit
    rms_before_mm: float  # the smaller fit's 3D residual RMS over the readings it kept
    rms_after_mm: float  # the fuller fit's

    def sentence(self) -> str:
        """What was added and why, in the numbers of the two fits."""
        sizes = [e["residual_mm"] for e in self.explained]
        span = f"{min(sizes):.4f}" + (f"-{max(sizes):.4f}" if len(sizes) > 1 else "")
        ids = ", ".join(str(e["pose_id"]) for e in self.explained[:8])
        ids += " ..." if len(self.explained) > 8 else ""
        still = (
            f"; {self.rejected_after} reading(s) still rejected"
            if self.rejected_after
            else "; no reading rejected"
        )
        return (
            f"fuller model kept: the error model lacks {self.what}; with "
            f"{', '.join(p.name for p in self.added)} added, {len(self.explained)} of the "
            f"{self.rejected_before} reading(s) the error model's fit rejected as gross "
            f"outliers (residuals {span} mm, above its limit of {self.limit_before_mm:.4f} mm; "
            f"poses {ids}) lie within the fuller fit's limit of {self.limit_after_mm:.4f} mm "
            f"and are kept{still}; residual {self.rms_before_mm:.4f} mm RMS on the readings kept "
            f"before, {self.rms_after_mm:.4f} mm now"
        )

    def as_dict(self) -> dict:
        return {
            "text": self.sentence(),
            "added": [p.name for p in self.added],
            "what": self.what,
            "kept_readings": list(self.explained),
            "rejected_before": self.rejected_before,
            "rejection_limit_before_mm": self.limit_before_mm,
            "rejected_after": self.rejected_after,
            "rejection_limit_after_mm": self.limit_after_mm,
            "residual_rms_before_mm": self.rms_before_mm,
            "residual_rms_after_mm": self.rms_after_mm,
        }


def fuller_or_not(
    model: CalibrationModel,
    picked: Dataset,
    obs: Observations,
    result: IdentificationResult,
    choice: Any,
    fit: Callable[[CalibrationModel], tuple[IdentificationResult, Any]],
) -> tuple[CalibrationModel, IdentificationResult, Any, FullerModel | None]:
    """(model, result, ``fit``'s second answer, why) of the fit with the error model's fuller
    variant when it explains readings the fit of ``model`` (``result``) rejects as gross
    outliers; else of the fit as it was (why: None). ``fit(model)`` fits a model to ``obs``,
    the observations of ``picked``. Tried for readings in the base frame only (a tracker's
    registration absorbs the base's placement)."""
    if not result.rejected or obs.frame != "base":
        return model, result, choice, None
    added = base_placement(model, result.values, obs.commands)
    if not added:
        return model, result, choice, None
    fuller = with_parameters(model, added)
    try:
        wider, wider_choice = fit(fuller)
    except (CalibError, TwinError):  # the fuller fit failed: the error model's stands
        return model, result, choice, None
    kept = explained(result.rejected, wider.rejected)
    if kept is None or (result.converged and not wider.converged):
        return model, result, choice, None
    names = model.nominal.target_names
    why = FullerModel(
        added=tuple(added),
        what="the placement of the machine's base in the world (readings in the base frame: "
        "no registration absorbs it)",
        explained=tuple(
            {
                "pose_id": int(picked.pose_ids[r.pose_index]),
                "target": names[r.target_index],
                "residual_mm": float(r.residual_m * 1e3),
            }
            for r in kept
        ),
        rejected_before=len(result.rejected),
        limit_before_mm=rejection_limit_m(result.robust_scale_m) * 1e3,
        rejected_after=len(wider.rejected),
        limit_after_mm=rejection_limit_m(wider.robust_scale_m) * 1e3,
        rms_before_mm=float(np.sqrt(3.0) * result.residual_rms * 1e3),
        rms_after_mm=float(np.sqrt(3.0) * wider.residual_rms * 1e3),
    )
    return fuller, wider, wider_choice, why
