"""The loop closed on the polisher: diagnose the fine residual, model the effect, refit, compensate.

After the fine calibration (OLS on the identifiable set) the residual of the calibration
layers goes to the residual diagnosis (calib.diagnosis.core). The effect it names becomes a
correction of the actuator commands (calib.loop.effect); the full nonlinear model, geometry
of the identifiable set and the effect's coefficients together, is refitted to the same
readings by Levenberg-Marquardt (calib.loop.fit), and the NC poses are compensated by the
fixed-point inversion of the corrected model (calib.loop.compensation), then re-measured.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import special

from calib.analysis import analyse
from calib.data import Dataset, write_dataset
from calib.diagnosis import Diagnosis, diagnose
from calib.fit import IdentificationResult, Observations
from calib.loop import (
    ActuatorCorrection,
    LoopFit,
    diagnosed_correction,
    fit_with_effect,
    loop_commands,
    residual_rms_3d,
)
from scenarios.files_loop import loop_through_files
from scenarios.studies.liu_vs_ols.pipeline import Bench, Calibration
from scenarios.twin_datasets import machine_fields
from twin.kinematics import on_one_blas_thread
from twin.measurement import measure as twin_measure

# the level at which a residual exceeds the noise: the diagnosis's own (diagnose's alpha)
NOISE_ALPHA = 0.01


def loop_verdict(
    chosen: str,
    reason: str,
    modelled: bool,
    refit_p: float,
    after_mm: float,
    floor_mm: float,
) -> tuple[str, str]:
    """The loop's label and why. The diagnosis reads the one-step fine OLS, whose residual
    may exceed the noise by its linearisation alone; when it modelled nothing and the
    nonlinear refit of the geometry leaves a residual that passes the chi-square noise test
    (p >= NOISE_ALPHA), there is no effect: "none". Otherwise the diagnosis's label."""
    if modelled or refit_p < NOISE_ALPHA or chosen == "none":
        return chosen, reason
    return "none", (
        f"the diagnosis said {chosen} of the one-step fine OLS's residual, but the nonlinear "
        f"refit of the geometry alone leaves {after_mm:.4f} mm against the noise floor "
        f"{floor_mm:.4f} mm (3D RMS per reading), within the noise (chi-square p = "
        f"{refit_p:.3g} >= {NOISE_ALPHA:g}): what the one-step estimate left was its "
        "linearisation, no effect"
    )


def chi_square_p(sum_sq: float, sigma: float, dof: int) -> float:
    """P(chi-square with ``dof`` degrees of freedom >= sum_sq / sigma^2)."""
    return float(special.chdtrc(max(dof, 1), sum_sq / sigma**2))


@dataclass(frozen=True)
class Loop:
    diagnosis: Diagnosis
    fit: LoopFit
    residual_rms_before_mm: float  # 3D per reading, fine (OLS) geometry, nonlinear model
    residual_rms_after_mm: float  # 3D per reading, geometry and effect refitted
    noise_floor_rms_mm: float  # 3D per reading of the tracker noise: sqrt(3) sigma / sqrt(n)
    refit_chi2_p_value: float  # the refitted residual against the tracker noise

    def verdict(self) -> tuple[str, str]:
        """The loop's label and why (:func:`loop_verdict`)."""
        d = self.diagnosis
        return loop_verdict(
            d.chosen,
            d.reason,
            bool(self.fit.correction.names),
            self.refit_chi2_p_value,
            self.residual_rms_after_mm,
            self.noise_floor_rms_mm,
        )

    def commands(
        self,
        bench: Bench,
        poses: np.ndarray,
        order: np.ndarray,
        near: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """``near``: the poses' configurations and actuator twist Jacobians on a nearby model
        (see calib.loop.compensation.loop_commands)."""
        return loop_commands(
            bench.model, self.fit.values, self.fit.correction, poses, order, near=near
        ).commands

    def summary(self) -> dict[str, Any]:
        d = self.diagnosis
        corr = self.fit.correction
        chosen, reason = self.verdict()
        return {
            "diagnosed_effect": chosen,
            "reason": reason,
            "diagnosis_said": d.chosen,  # of the one-step fine OLS's residual
            "refit_chi2_p_value": self.refit_chi2_p_value,
            "residual_rms_before_mm": self.residual_rms_before_mm,
            "residual_rms_after_mm": self.residual_rms_after_mm,
            "noise_floor_rms_mm": self.noise_floor_rms_mm,
            "chi2_p_value": d.chi2_p_value,
            "modelled": list(corr.names),
            "coefficients": {n: float(v) for n, v in zip(corr.names, corr.theta, strict=True)},
            "coefficient_std": {
                n: float(s)
                for n, s in zip(
                    corr.names, self.fit.std_errors[len(self.fit.columns) :], strict=True
                )
            },
            "lm_iterations": self.fit.iterations,
            "lm_converged": self.fit.converged,
            "gauss_newton_polish_steps": self.fit.polish_steps,
            "notes": list(d.notes),
        }


def fine_result(bench: Bench, cal: Calibration, values: np.ndarray) -> IdentificationResult:
    """The fine calibration (``values``: coarse settings + the OLS estimate on the
    identifiable set) as the identification result the diagnosis reads."""
    names = bench.model.params.names
    mask = np.zeros(len(names), dtype=bool)
    mask[cal.problem.columns] = True
    pred = bench.model.predict(values, cal.fine_commands)
    jac = bench.model.jacobian(values, pred)
    r = (cal.fine_measured - pred.targets).reshape(-1)
    return IdentificationResult(
        names=names,
        values=values,
        estimated=mask,
        std_errors=np.full(len(names), np.nan),
        covariance=np.zeros((int(mask.sum()), int(mask.sum()))),
        residual_rms=float(np.sqrt(np.mean(r**2))),
        iterations=1,
        converged=True,
        history=[],
        report=analyse(jac[:, mask], [n for n, m in zip(names, mask, strict=True) if m]),
    )


@on_one_blas_thread  # small matrices throughout (at most 294 x 57)
def close_loop(bench: Bench, cal: Calibration, estimator: str = "ols") -> Loop:
    model = bench.model
    values = cal.estimates[estimator][1]
    obs = Observations(cal.fine_commands, cal.fine_measured)
    result = fine_result(bench, cal, values)
    diag = diagnose(
        model,
        obs,
        result,
        bench.sigma_m,
        order=cal.fine_order,
        tracker_position_m=np.asarray(bench.tracker.position_m),
    )
    start = values.copy()
    if diag.geometry_correction is not None:
        start[result.estimated] += diag.geometry_correction
    correction: ActuatorCorrection = diagnosed_correction(
        model, start, diag.coefficients, diag.time_origin, diag.time_unit
    )
    fit = fit_with_effect(
        model,
        start,
        cal.problem.columns,
        correction,
        cal.fine_commands,
        cal.fine_order,
        cal.fine_measured,
    )
    before = residual_rms_3d(cal.fine_measured, model.predict(values, cal.fine_commands).targets)
    sigma = bench.sigma_m / np.sqrt(bench.tracker.repeats)  # per coordinate of a reading
    floor = np.sqrt(3.0) * sigma
    n_readings = cal.fine_measured.size // 3
    dof = 3 * n_readings - len(fit.columns) - len(correction.theta)
    refit_p = chi_square_p(fit.residual_rms_3d_m**2 * n_readings, sigma, dof)
    return Loop(diag, fit, before * 1e3, fit.residual_rms_3d_m * 1e3, float(floor) * 1e3, refit_p)


def readings_dataset(
    bench: Bench, cal: Calibration, test_commands: np.ndarray, seed: int
) -> Dataset:
    """The fine plan's readings (set ``calibration``, the very readings the loop above
    fitted) and the test layer's nodes at the coarse settings measured next in the sequence
    (set ``test``), as the tracker hands them over. The test readings come from a twin of
    the machine in the same state (the fine plan's sequence run again on a generator of
    their own, ``seed``, its readings dropped), so that the bench's clock and draws, and with
    them every other number of the study, are untouched."""
    nominal = bench.machine.nominal
    n_fine, n_test = len(cal.fine_commands), len(test_commands)
    order = np.concatenate([cal.fine_order, cal.fine_order[-1] + 1 + np.arange(n_test)])
    commands = np.vstack([cal.fine_commands, test_commands])
    rng = np.random.default_rng(seed)
    m = twin_measure(
        bench.machine.truth, commands, bench.tracker, rng, effects=bench.effects, order=order
    )
    readings = np.concatenate([cal.fine_measured[:, :, None, :], m.readings[n_fine:]])
    return Dataset(
        **machine_fields(nominal),
        frame="base",
        pose_ids=np.arange(n_fine + n_test),
        sets=np.array(["calibration"] * n_fine + ["test"] * n_test),
        commands=commands,
        readings=readings,
        order=order,
        tracker={
            "position_mm": [v * 1e3 for v in bench.tracker.position_m],
            "noise": bench.tracker.noise.describe(),
            "repeats": bench.tracker.repeats,
        },
    )


def close_loop_through_files(
    bench: Bench, cal: Calibration, test_commands: np.ndarray, out_dir: Path
) -> dict[str, Any]:
    """The loop as a user runs it on the polisher's readings (scenarios.files_loop)."""
    seed = bench.scenario.get("seed", int) + 1  # the test readings' own draws
    ds = readings_dataset(bench, cal, test_commands, seed)
    (out_dir / "datasets").mkdir(parents=True, exist_ok=True)
    data = write_dataset(ds, out_dir / "datasets" / "readings.csv")
    sc = bench.scenario
    return loop_through_files(
        sc.resolve(sc.get("model", str), "model"),
        sc.resolve(sc.get("error_model", str), "error_model"),
        data,
        out_dir / "loop_through_files",
        bench.sigma_m * 1e3,
    )
