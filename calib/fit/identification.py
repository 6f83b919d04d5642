"""Identification of geometric parameters from a Dataset (target residual, Levenberg-Marquardt).

The residual is measured minus predicted target position, for every pose and target (the
mean of the repeats), in the base frame; readings in the tracker's own frame are carried
into it by a registration estimated with the parameters (calib.fit.registration). This is
equivalent to the second paper's Eq. 5 (which compares limb lengths recomputed from measured
poses) but needs no pose fit, uses every measured coordinate, and works for any machine the
MJCF describes.

Robust by default (calib.fit.robust): gross outliers are found, listed and left out. With a
``prior`` (calib.fit.prior) the fit is the maximum a posteriori estimate.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from calib.analysis.identifiability import (
    IdentifiabilityReport,
    analyse,
    zero_columns,
)
from calib.estimators.levenberg_marquardt import LMOptions, levenberg_marquardt
from calib.exceptions import IdentifiabilityError
from calib.fit.model import CalibrationModel, Prediction
from calib.fit.observations import FRAMES, Observations, bind_dataset, model_from_files
from calib.fit.prior import Prior, padded_rows, physical_ranges
from calib.fit.probe_rows import ProbeRows, interleave
from calib.fit.redundancy import Explainer, choose_fixed, with_choice
from calib.fit.registration import (
    NAMES as REGISTRATION_NAMES,
)
from calib.fit.registration import (
    Registration,
    about,
    about_jacobian,
    centred,
    initial_registration,
    project_out,
    registration_jacobian,
    rigid_motion_span,
)
from calib.fit.regularisation import SubspaceChoice, choose_subspace, creeping_cuts
from calib.fit.robust import (
    LOSS_WEIGHTS,
    Rejection,
    RobustOptions,
    rejections,
    robust_fit,
    robust_scale,
    suspect_outliers,
)
from calib.fit.verdict import implausible_estimates
from twin.exceptions import ClosureError
from twin.kinematics.structure import one_blas_thread
from twin.mechanism import Mechanism
from twin.parameters import Parameter

REDUNDANT = "redundant with the tracker registration (the tracker's frame absorbs it)"

__all__ = [
    "LOSS_WEIGHTS",
    "REGISTRATION_NAMES",
    "IdentificationResult",
    "Observations",
    "Rejection",
    "RobustOptions",
    "bind_dataset",
    "identify",
    "model_from_files",
    "robust_scale",
]


@dataclass(frozen=True)
class IdentificationResult:
    names: tuple[str, ...]
    values: np.ndarray  # SI, every parameter (the unestimated keep their start value)
    estimated: np.ndarray  # bool mask
    std_errors: np.ndarray  # SI, NaN where not estimated; from the kept readings
    covariance: np.ndarray  # over the estimated parameters (then the registration's 6)
    residual_rms: float  # metres, per coordinate, over the kept readings
    iterations: int  # Levenberg-Marquardt iterations, every stage included
    converged: bool  # of the final least-squares fit
    history: list[float]  # cost after each accepted step of the final least-squares fit
    report: IdentifiabilityReport  # of all readings, at the start values
    rejected: tuple[Rejection, ...] = ()  # gross outliers left out, by pose then target
    robust_scale_m: float = float("nan")  # per-coordinate robust noise scale s (metres)
    convergence_message: str = ""
    registration: Registration | None = None  # base_from_tracker, for tracker-frame data
    registration_std: np.ndarray | None = None  # (6,): metres, radians
    redundant_with_registration: tuple[str, ...] = ()
    prior: Prior | None = None
    # the fit's last linearisation over the kept readings: d residual / d (free parameters,
    # then the registration's 6), the residual (measured - predicted, m) and each row's pose
    fit_jacobian: np.ndarray | None = None
    fit_residual: np.ndarray | None = None
    fit_pose_of_row: np.ndarray | None = None
    subspace: SubspaceChoice | None = None  # the weak directions kept at zero, if asked

    def residuals_m(self, model: CalibrationModel, obs: Observations) -> np.ndarray:
        """3D residual norms (P, T) of every reading at this estimate, in the base frame."""
        measured = (
            obs.measured if self.registration is None else self.registration.to_base(obs.measured)
        )
        pred = model.predict(self.values, obs.commands)  # warm from the fit's own solves
        return np.linalg.norm(measured - pred.targets, axis=-1)


def identify(
    model: CalibrationModel,
    obs: Observations,
    x0: np.ndarray | None = None,
    unidentifiable: str = "raise",
    options: LMOptions | None = None,
    robust: bool = True,
    robust_options: RobustOptions | None = None,
    prior: Prior | None = None,
    subspace: str = "full",
) -> IdentificationResult:
    """Estimate the parameters; ``unidentifiable`` is "raise" or "fix" (keep them at x0).

    ``robust`` (default) rejects gross outliers (calib.fit.robust); ``robust=False`` is plain
    least squares over every reading. ``prior`` (std per parameter, SI) adds a Gaussian
    prior of zero mean. Readings with ``obs.frame == "tracker"`` get a registration.
    ``subspace="auto"`` estimates in the subspace the data determine and keeps the weak
    directions at zero (calib.fit.regularisation.choose_subspace); "full" estimates every
    identifiable parameter."""
    if model.offsets is not None:  # the offset kinds read the readings' state
        model.bind_state(obs.state)
    if unidentifiable not in ("raise", "fix"):
        raise ValueError(f"unidentifiable must be 'raise' or 'fix', got {unidentifiable!r}")
    if obs.frame not in FRAMES:
        raise ValueError(f"observations frame must be one of {FRAMES}, got {obs.frame!r}")
    if subspace not in ("full", "auto"):
        raise ValueError(f"subspace must be 'full' or 'auto', got {subspace!r}")
    if subspace == "auto" and prior is not None:
        raise ValueError("a prior and a truncated subspace are two answers to one question")
    if prior is not None and np.shape(prior.std) != (model.n_parameters,):
        raise ValueError(f"prior std must have one entry per parameter ({model.n_parameters})")
    with one_blas_thread():
        plain = _identify(model, obs, x0, unidentifiable, options, robust, robust_options, prior)
        if subspace == "full":
            return plain
        free = plain.estimated
        ranges = physical_ranges(model.params)[free]
        params = model.params
        start_free = np.zeros(int(free.sum())) if x0 is None else np.asarray(x0, float)[free]
        names = tuple(np.asarray(params.names)[free])
        units = np.asarray(params.display_units(), dtype=object)[free]
        std = params.to_display(plain.std_errors)[free]

        def implausible(values: np.ndarray, allow_std: bool = True) -> tuple[str, ...]:
            """Estimates (SI, from the start) beyond a plausible size, by 3 of the plain
            fit's standard errors (the verdict's rule), or by any amount."""
            full = np.zeros(model.n_parameters)
            full[free] = start_free + values
            shown = params.to_display(full)[free]
            return implausible_estimates(names, shown, units, std if allow_std else None)

        choice = choose_subspace(
            plain.fit_jacobian,
            plain.fit_residual,
            plain.values[free] - (0.0 if x0 is None else np.asarray(x0, dtype=float)[free]),
            ranges,
            plain.fit_pose_of_row,
            one_se=plain.converged,
            # the offset kinds' sizes are no machine's known size: estimated in full
            always=np.asarray(model.params.is_offset, dtype=bool)[free],
            # a plain fit that did not converge is no answer to judge: the creeping path below
            implausible=implausible if plain.converged else None,
        )
        res = plain
        if choice.basis is not None:
            res = _identify(
                model, obs, x0, unidentifiable, options, robust, robust_options, None,
                choice.basis, (plain.report, plain.redundant_with_registration),
            )  # fmt: skip
        if res.converged or plain.converged:
            return replace(res, subspace=choice)
        # no converged answer: the plain fit crept along its weak directions; the mildest
        # truncation that converges, fitted from the start (calib.fit.regularisation)
        for creep in creeping_cuts(plain.fit_jacobian, plain.fit_residual, ranges):
            res = _identify(
                model, obs, x0, unidentifiable, options, robust, robust_options, None,
                creep.basis, (plain.report, plain.redundant_with_registration),
            )  # fmt: skip
            if res.converged:
                return replace(res, subspace=creep)
        return replace(plain, subspace=choice)


def _analysed(jac: np.ndarray, names: tuple[str, ...]) -> IdentifiabilityReport:
    """:func:`calib.analysis.identifiability.analyse` of a tall Jacobian through its QR factor
    ``R``:
    ``J = Q R`` with orthonormal ``Q`` keeps every column norm, singular value, pivoted-QR
    choice and least-squares coefficient, in n rows instead of m (a 2304 x 54 hexapod
    Jacobian: 54 rows, a tenth of the identification's time saved). The report still counts
    the m equations."""
    m, n = jac.shape
    if m <= 2 * n:
        return analyse(jac, names)
    return replace(analyse(np.linalg.qr(jac, mode="r"), names), n_rows=m)


def _analyse(
    jac0: np.ndarray,
    names: tuple[str, ...],
    reg_jac: np.ndarray | None,
    residual: np.ndarray | None = None,
    ranges: np.ndarray | None = None,
    mech: Mechanism | None = None,
    parameters: tuple[Parameter, ...] = (),
) -> tuple[IdentifiabilityReport, tuple[str, ...]]:
    """Identifiability of the kinematic parameters beside the registration (if any), and
    which of them the registration makes redundant. With the start ``residual`` (and the
    parameters' physical ``ranges``, SI), the member of each exactly redundant group that is
    fixed is the one whose removal keeps the estimates smallest (calib.fit.redundancy), and each
    fixed parameter's reason names its true partners."""
    jac = jac0 if reg_jac is None else project_out(jac0, reg_jac)
    report = _analysed(jac, names)
    if residual is not None and ranges is not None and report.rank < len(names):
        r = residual if reg_jac is None else project_out(residual[:, None], reg_jac)[:, 0]
        zero = zero_columns(jac0)  # no effect at all (not only through the registration)
        red = choose_fixed(
            jac,
            r,
            ranges,
            len(names) - report.rank,
            zero,
            None if reg_jac is None else jac0,
        )
        return with_choice(report, red, jac, Explainer(mech, parameters), REDUNDANT)
    if reg_jac is None:
        return report, ()
    alone = _analysed(jac0, names)
    redundant = tuple(n for n in names if n in alone.identifiable and n not in report.identifiable)
    why = dict(report.unidentifiable)
    for n in redundant:
        why[n] = REDUNDANT
    return replace(report, unidentifiable=why), redundant


def _identify(
    model,
    obs,
    x0,
    unidentifiable,
    options,
    robust,
    robust_options,
    prior,
    basis=None,
    analysed=None,
):
    n = model.n_parameters
    names = model.params.names
    x_start = np.zeros(n) if x0 is None else np.array(x0, dtype=float)
    commands, measured = obs.commands, obs.measured
    n_poses = len(commands)
    probe = ProbeRows.of(model.nominal, obs.rotations, obs.orientation_weight_m)
    # a probe's orientation rows are one more reading of its pose (calib.fit.probe_rows)
    n_targets = measured.shape[1] + (0 if probe is None else probe.n)
    n_readings = n_poses * n_targets
    first = model.predict(x_start, commands)
    geo0 = jac0 = model.jacobian(x_start, first)
    if probe is not None:
        ang0 = model.tool_twist_jacobian(x_start, first.qpos)[:, 3:, :]
        jac0 = interleave(geo0, -probe.jacobian(ang0, None)[0], n_poses)
    reg0 = jreg0 = None
    centre = np.zeros(3)
    ranges = physical_ranges(model.params)
    if obs.frame == "tracker":  # the rotation turns about the readings' centre
        measured, centre = centred(measured)
        reg0 = initial_registration(measured, first.targets)
        jreg0 = rigid_motion_span(first.targets)  # at the model's points: structure only
        r0 = (reg0.to_base(measured) - first.targets).reshape(-1)
        if probe is not None:
            jreg0 = interleave(jreg0, probe.registration_span(n_poses), n_poses)
    else:
        r0 = (measured - first.targets).reshape(-1)
    if probe is not None:
        rot0 = None if reg0 is None else reg0.rotation
        r0 = interleave(r0, probe.residual(model.mechanism(x_start), first.qpos, rot0), n_poses)
    # a refit in a subspace of the plain fit's parameters takes the plain fit's analysis (the
    # same start: a rank decided again from a differently warm-started Jacobian can differ)
    report, redundant = analysed or _analyse(
        jac0, names, jreg0, r0, ranges, model.nominal, model.params.parameters
    )
    if report.n_identifiable < n and unidentifiable == "raise":
        raise IdentifiabilityError(
            f"{len(commands)} poses cannot identify all {n} parameters:\n{report.summary()}"
        )
    mask = np.array([nm in report.identifiable for nm in names])
    free = np.flatnonzero(mask)
    k = len(free) if basis is None else basis.shape[1]
    start_free = x_start[free] if basis is None else np.zeros(k)
    z_start = start_free if reg0 is None else np.concatenate([start_free, reg0.start_vector()])
    prior_w = None if prior is None else prior.weights()[free]

    def split(z: np.ndarray) -> tuple[np.ndarray, Registration | None]:
        x = x_start.copy()
        x[free] = z[:k] if basis is None else x_start[free] + basis @ z[:k]
        return x, (None if reg0 is None else reg0.moved(z[k:]))

    def problem(rows: np.ndarray | None):
        """Residual and Jacobian of the readings' rows ``rows`` (None: all), then the prior's."""

        def residual(
            z: np.ndarray, pred: Prediction | None = None
        ) -> tuple[np.ndarray, Prediction]:
            x, reg = split(z)
            pred = model.predict(x, commands) if pred is None else pred
            meas = measured if reg is None else reg.to_base(measured)
            r = (meas - pred.targets).reshape(-1)
            if probe is not None:
                rot = None if reg is None else reg.rotation
                r_o = probe.residual(model.mechanism(x), pred.qpos, rot)
                r = interleave(r, r_o, n_poses)
            r = r if rows is None else r[rows]
            if prior_w is not None:
                r = np.concatenate([r, -padded_rows(prior_w, z[:k] - x_start[free])[0]])
            return r, pred

        def jacobian(z: np.ndarray, pred: Prediction, geo: np.ndarray | None = None) -> np.ndarray:
            x, _ = split(z)
            if geo is None and k == n and basis is None:  # every column: negated in place
                jac = model.jacobian(x, pred)
                np.negative(jac, out=jac)
            else:
                jac = -(model.jacobian(x, pred) if geo is None else geo)[:, free]
                if basis is not None:
                    jac = jac @ basis
            if reg0 is not None:
                jac = np.hstack([jac, registration_jacobian(reg0, z[k:], measured)])
            if probe is not None:
                ang = model.tool_twist_jacobian(x, pred.qpos)[:, 3:, :][:, :, free]
                ang = ang if basis is None else ang @ basis
                par, reg_o = probe.jacobian(ang, None if reg0 is None else z[k:])
                o = par if reg_o is None else np.concatenate([par, reg_o], axis=2)
                jac = interleave(jac, o, n_poses)
            jac = jac if rows is None else jac[rows]
            if prior_w is not None:
                pj = -padded_rows(prior_w, z[:k] - x_start[free])[1]
                jac = np.vstack([jac, np.hstack([pj, np.zeros((len(pj), len(z) - k))])])
            return jac

        return residual, jacobian

    n_unknown = len(z_start)
    residual, jacobian = problem(None)
    # the model's prediction and Jacobian at the start (x_start, the registration's start)
    # are the fit's first evaluation: no second closure solve and Jacobian for it
    start = (residual(z_start, first)[0], jacobian(z_start, first, geo0))
    res = levenberg_marquardt(residual, jacobian, z_start, options, (ClosureError,), start)
    iterations = res.iterations
    norms = np.linalg.norm(res.residual[: 3 * n_readings].reshape(-1, 3), axis=1)
    scale = robust_scale(norms, n_unknown)
    rejected: tuple[Rejection, ...] = ()
    n_kept = n_readings
    opt = robust_options or RobustOptions()
    jtj = res.jacobian.T @ res.jacobian  # the screen's and the covariance's
    if robust and suspect_outliers(res.residual, res.jacobian, n_readings, n_unknown, opt, jtj):
        rob = robust_fit(residual, jacobian, res.x, n_unknown, opt, n_readings)
        iterations += rob.iterations
        norms = np.linalg.norm(rob.residual[: 3 * n_readings].reshape(-1, 3), axis=1)
        bad, rejected, scale = rejections(norms, n_unknown, n_targets, opt)
        if rejected:  # else the least-squares fit over every reading is the answer
            rows = np.repeat(~bad, 3)
            n_kept = int(np.sum(~bad))
            kept, _ = _analyse(
                jac0[rows][:, free], report.identifiable, None if reg0 is None else jreg0[rows]
            )
            lost = [nm for nm in report.identifiable if nm not in kept.identifiable]
            if lost:
                raise IdentifiabilityError(
                    f"after rejecting {len(rejected)} outlying readings the kept ones cannot "
                    f"identify {lost}:\n{kept.summary()}"
                )
            residual, jacobian = problem(rows)
            base = options or LMOptions()
            near = replace(base, initial_damping=min(base.initial_damping, 1e-6))
            res = levenberg_marquardt(residual, jacobian, rob.fit.x, near, (ClosureError,))
            iterations += res.iterations
            jtj = res.jacobian.T @ res.jacobian
    m = 3 * n_kept
    r_meas = res.residual[:m]
    pose_of_row = np.repeat(np.arange(n_poses), 3 * n_targets)
    if rejected:
        pose_of_row = pose_of_row[rows]
    dof = max(m - n_unknown, 1)
    sigma2 = float(r_meas @ r_meas) / dof
    cov = sigma2 * np.linalg.pinv(jtj)
    kf = len(free)
    if basis is not None:  # over the free parameters (then the registration)
        t = np.zeros((kf + len(z_start) - k, len(z_start)))
        t[:kf, :k] = basis
        t[kf:, k:] = np.eye(len(z_start) - k)
        cov = t @ cov @ t.T
    std = np.full(n, np.nan)
    std[free] = np.sqrt(np.clip(np.diag(cov)[:kf], 0, None))
    values, reg = split(res.x)
    if reg is not None:  # from the centred readings back to the readings themselves
        carry = np.eye(len(cov))
        carry[kf:, kf:] = about_jacobian(reg0, res.x[k:], centre)
        cov = carry @ cov @ carry.T
        reg = about(reg, centre)
    return IdentificationResult(
        names=names,
        values=values,
        estimated=mask,
        std_errors=std,
        covariance=cov,
        residual_rms=float(np.sqrt(float(r_meas @ r_meas) / m)),
        iterations=iterations,
        converged=res.converged,
        history=res.history,
        report=report,
        rejected=rejected,
        robust_scale_m=scale,
        convergence_message=res.message,
        registration=reg,
        registration_std=None if reg is None else np.sqrt(np.clip(np.diag(cov)[kf:], 0, None)),
        redundant_with_registration=redundant,
        prior=prior,
        fit_jacobian=res.jacobian[:m],
        fit_residual=r_meas,
        fit_pose_of_row=pose_of_row,
    )
