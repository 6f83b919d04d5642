"""Identification: ours (calib.fit.identification, robust and plain) against scipy's least_squares
with
a finite-difference Jacobian, each on a fresh CalibrationModel, best of N, answers compared.

The baseline is what a user would write first: ``least_squares(method="lm", jac="2-point",
x_scale="jac")`` over the same free (identifiable) parameters, from the same start (zero),
with tolerances as tight as ours (our LM stops on a step below 1e-12 SI or a relative cost
decrease below 1e-14). Both run with BLAS on one thread (ours pins it inside
calib.fit.identification,
the baseline here), so neither pays for thread hand-offs on small matrices.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import least_squares

from bench.machines import BenchMachine
from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from twin.kinematics.structure import one_blas_thread

SCIPY_OPTIONS = {"method": "lm", "jac": "2-point", "x_scale": "jac", "ftol": 1e-14, "xtol": 1e-12}
# the same problem with our Jacobian: "trf" (MINPACK's "lm" takes no callable Jacobian's
# structure into account and is no faster), tolerances as tight as ours
SCIPY_ANALYTIC_OPTIONS = {"method": "trf", "x_scale": "jac", "ftol": 1e-14, "xtol": 1e-12}


def _ours(m: BenchMachine, robust: bool, repeat: int) -> tuple[float, object]:
    best, result = np.inf, None
    for _ in range(repeat):
        model = CalibrationModel(m.nominal, m.params)  # fresh: no warm start, no cache
        t0 = time.perf_counter()
        result = identify(model, m.obs, unidentifiable=m.unidentifiable, robust=robust)
        best = min(best, time.perf_counter() - t0)
    return best, result


def _scipy(m: BenchMachine, free: np.ndarray, repeat: int, budget_s: float):
    best, sol, runs = np.inf, None, 0
    n = len(m.params)
    for _ in range(repeat):
        model = CalibrationModel(m.nominal, m.params)  # fresh for every run

        def resid(z: np.ndarray, model: CalibrationModel = model) -> np.ndarray:
            x = np.zeros(n)
            x[free] = z
            return (m.obs.measured - model.predict(x, m.obs.commands).targets).reshape(-1)

        t0 = time.perf_counter()
        with one_blas_thread():
            sol = least_squares(resid, np.zeros(len(free)), **SCIPY_OPTIONS)
        best = min(best, time.perf_counter() - t0)
        runs += 1
        if best * (runs + 1) > budget_s:  # another run would exceed the budget
            break
    return best, sol, runs


def _scipy_analytic(m: BenchMachine, free: np.ndarray, repeat: int):
    """scipy's least_squares (trf, the same tolerances) given our analytic Jacobian: what a
    user with the project's model and Jacobian but not its Levenberg-Marquardt would get."""
    best, sol = np.inf, None
    n = len(m.params)
    for _ in range(repeat):
        model = CalibrationModel(m.nominal, m.params)
        cache: dict = {}

        def resid(z: np.ndarray, model: CalibrationModel = model, cache: dict = cache):
            x = np.zeros(n)
            x[free] = z
            pred = model.predict(x, m.obs.commands)
            cache["z"], cache["x"], cache["pred"] = z.copy(), x, pred
            return (m.obs.measured - pred.targets).reshape(-1)

        def jac(z: np.ndarray, model: CalibrationModel = model, cache: dict = cache):
            if "z" not in cache or not np.array_equal(cache["z"], z):
                resid(z)
            return -model.jacobian(cache["x"], cache["pred"])[:, free]

        t0 = time.perf_counter()
        with one_blas_thread():
            sol = least_squares(resid, np.zeros(len(free)), jac=jac, **SCIPY_ANALYTIC_OPTIONS)
        best = min(best, time.perf_counter() - t0)
    return best, sol


def compare(m: BenchMachine, repeat: int = 3, scipy_budget_s: float = 240.0) -> dict:
    """Times and answers of ours (robust default, and plain) and of the scipy FD baseline."""
    t_rob, rob = _ours(m, True, repeat)
    t_ols, ols = _ours(m, False, repeat)
    free = np.flatnonzero(rob.estimated)
    t_fd, fd, runs = _scipy(m, free, repeat, scipy_budget_s)
    t_an, an = _scipy_analytic(m, free, repeat)
    x_fd = np.zeros(len(m.params))
    x_fd[free] = fd.x
    disp = m.params.to_display
    diff_rob = np.abs(disp(rob.values - x_fd))[free]
    diff_ols = np.abs(disp(ols.values - x_fd))[free]
    ang = m.params.is_angle[free]
    in_std = np.abs(rob.values - x_fd)[free] / rob.std_errors[free]
    rms_fd = float(np.sqrt(np.mean(fd.fun**2)))
    return {
        "n_poses": len(m.obs.commands),
        "poses": m.plan,
        "n_parameters": len(m.params),
        "n_identified": len(free),
        "identify_ours_s": t_rob,
        "identify_ours_plain_s": t_ols,
        "identify_scipy_fd_s": t_fd,
        "identify_speedup_vs_scipy_fd": t_fd / t_rob,
        "identify_plain_speedup_vs_scipy_fd": t_fd / t_ols,
        "identify_scipy_analytic_s": t_an,
        "identify_speedup_vs_scipy_analytic": t_an / t_rob,
        "identify_scipy_analytic_nfev": int(an.nfev),
        "residual_rms_scipy_analytic_um": float(np.sqrt(np.mean(an.fun**2))) * 1e6,
        "identify_ours_iterations": rob.iterations,
        "identify_ours_rejected": len(rob.rejected),
        "identify_scipy_fd_nfev": int(fd.nfev),
        "identify_scipy_fd_status": int(fd.status),
        "identify_scipy_fd_runs": runs,
        "identify_ours_repeats": repeat,
        "identify_ours_vs_scipy_max_abs_diff_mm": float(np.max(diff_rob[~ang], initial=0.0)),
        "identify_ours_vs_scipy_max_abs_diff_deg": float(np.max(diff_rob[ang], initial=0.0)),
        "identify_plain_vs_scipy_max_abs_diff_mm": float(np.max(diff_ols[~ang], initial=0.0)),
        "identify_plain_vs_scipy_max_abs_diff_deg": float(np.max(diff_ols[ang], initial=0.0)),
        "identify_ours_vs_scipy_max_diff_in_std_errors": float(np.max(in_std)),
        "residual_rms_ours_um": rob.residual_rms * 1e6,
        "residual_rms_scipy_fd_um": rms_fd * 1e6,
    }
