"""The user's test set in a diagnosis: its residual, its context, its error after a model.

The test poses took no part in the geometric fit nor in the diagnosis's choice of shapes;
their residual is formed at the geometric estimate, and a model (geometry correction and
effects, or a kernel correction) is judged by the 3D position error per reading it leaves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.diagnosis.candidate import Candidate
from calib.diagnosis.context import Context, build_context
from calib.diagnosis.fit import Evaluation
from calib.diagnosis.problem import Problem
from calib.diagnosis.unexplained import features, kernel_correction
from calib.diagnosis.verdict import TestSet
from calib.fit.model import CalibrationModel, Prediction
from calib.fit.position_error import stats_mm
from calib.fit.registration import rigid_motion_span


@dataclass(frozen=True)
class TestResidual:
    __test__ = False  # not a pytest class

    r: np.ndarray  # (Nt, R) at the geometric estimate
    geo: np.ndarray  # (Nt, R, p) the estimated geometric parameters' columns


def stats_3d(e: np.ndarray) -> dict[str, float]:
    """3D position error per reading (target at pose) of a residual (N, T*3): rms, mean, max
    (mm) and the count."""
    norms = np.linalg.norm(e.reshape(len(e), -1, 3), axis=2)
    s = stats_mm(norms).as_dict()
    return {"rms_mm": s["rms_mm"], "mean_mm": s["mean_mm"], "max_mm": s["max_mm"], "n": s["n"]}


def test_context(
    model: CalibrationModel,
    values: np.ndarray,
    test: TestSet,
    t0: float,
    unit: str,
    ctx: Context,
    head: np.ndarray | None,
) -> Context:
    """The test poses as the candidates see them, on the calibration's time axis (measured
    after it when no order is given; approached from its last pose when they follow it)."""
    t = test.time_s if test.time_s is not None else test.order
    n = len(test.commands)
    t = np.arange(n) + ctx.time.max() + t0 + 1 if t is None else np.asarray(t, float)
    seq = np.argsort(ctx.time)
    previous = ctx.commands[seq[-1]] if np.min(t - t0) > ctx.time.max() else None
    return build_context(model, values, test.commands, t - t0, unit, previous=previous, head=head)


def rigid_columns(targets: np.ndarray) -> np.ndarray:
    """(N, T*3, 6): what a small rigid motion of the frame does to the targets (N, T, 3)."""
    n = len(targets)
    return rigid_motion_span(targets).reshape(n, -1, 6)


def test_residual(
    model: CalibrationModel,
    values: np.ndarray,
    estimated: np.ndarray,
    test: TestSet,
    tctx,
    registration: bool = False,
) -> TestResidual:
    """The test poses' residual and geometric columns (and the registration's rigid motion
    with ``registration``, as for the calibration poses)."""
    n = len(test.commands)
    r = (np.asarray(test.measured) - tctx.targets).reshape(n, -1)
    qpos = model.predict(values, test.commands).qpos
    jac = model.jacobian(values, Prediction(tctx.targets, qpos))
    p = int(np.sum(estimated))
    geo = jac[:, estimated].reshape(n, -1, p)
    if registration:
        geo = np.concatenate([geo, rigid_columns(tctx.targets)], axis=2)
    return TestResidual(r, geo)


def test_after(tr: TestResidual, tctx: Context, cands: list[Candidate], ev: Evaluation):
    """The test residual (Nt, R) after the geometry correction and effects of ``ev``."""
    e = tr.r - tr.geo @ ev.fit.beta
    if cands:
        xs = [c.design(tctx, s) for c, s in zip(cands, ev.shapes, strict=True)]
        e = e - np.concatenate(xs, axis=2) @ ev.fit.theta
    return e


def kernel_test(
    prob: Problem, x_cal: np.ndarray, keep: np.ndarray, tr: TestResidual, tctx: Context, group: str
) -> np.ndarray:
    """The test residual after a kernel correction over ``group`` fitted on all calibration
    poses (the geometry refitted with it)."""
    x_test = features(tctx)[group]
    both = Problem(np.vstack([prob.r, tr.r]), np.vstack([prob.geo, tr.geo]))
    n = len(prob.r)
    train = np.zeros(len(both.r), bool)
    train[:n] = True
    k = np.vstack([keep, np.ones(tr.r.shape, bool)])
    corrected, _ = kernel_correction(both, np.vstack([x_cal, x_test]), train, k)
    return corrected(~train)
