"""What the fine plan reads of the kept parameters: their combinations, one per singular
direction of the identification Jacobian in mm and deg, each with its estimate, standard
error and the truth as the plan reads it (the scenario side knows it; calib never does).

A kept parameter can still be estimated at hundreds of mm for errors drawn within a few: it
is then a member of a combination the readings cannot fix (its columns nearly cancel), and
what the readings do fix is the other combinations. A combination is *readable* when its
+-2 standard errors lie within the range the errors were drawn in: even an error at the edge
of that range would then stand out of the noise.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

MEMBER_SHARE = 0.3  # a parameter named as a member of a combination: |coefficient| >= this
MEMBERS_SHOWN = 3  # at most this many members named in a combination's label


@dataclass(frozen=True)
class Combinations:
    """Combinations of the kept parameters (rows of ``directions``: unit vectors over the
    parameters in mm and deg), ordered by standard error, smallest first."""

    names: list[str]
    directions: np.ndarray  # (m, m), row i the coefficients of combination i
    estimate: np.ndarray  # (m,) mm or deg
    std: np.ndarray  # (m,) the estimate's standard error along each direction
    truth: np.ndarray  # (m,) the truth as the plan reads it, along each direction
    rms_per_unit_mm: np.ndarray  # (m,) RMS change of the readings per unit of each
    bound: float  # the errors were drawn within +-bound (mm or deg)

    @property
    def readable(self) -> np.ndarray:
        return 2.0 * self.std <= self.bound

    def label(self, i: int) -> str:
        """The combination's largest members with their coefficients."""
        v = self.directions[i]
        order = [k for k in np.argsort(-np.abs(v), kind="stable") if abs(v[k]) >= MEMBER_SHARE]
        order = order[:MEMBERS_SHOWN] or [int(np.argmax(np.abs(v)))]
        terms = " ".join(f"{v[k]:+.2f} {self.names[k]}" for k in order)
        return terms + (" ..." if np.sum(np.abs(v) >= MEMBER_SHARE) > len(order) else "")

    def unreadable_members(self) -> list[str]:
        """The parameters that are members of a combination the plan cannot read."""
        rows = self.directions[~self.readable]
        hit = np.any(np.abs(rows) >= MEMBER_SHARE, axis=0) if len(rows) else []
        return [n for n, h in zip(self.names, hit, strict=False) if h]


def plan_combinations(
    h_shown: np.ndarray,
    estimate: np.ndarray,
    covariance: np.ndarray,
    truth: np.ndarray,
    bound: float,
    names: list[str],
) -> Combinations:
    """The combinations of ``h_shown`` (readings in metres per mm or deg of each kept
    parameter): the right singular vectors, each signed so that its largest coefficient is
    positive. ``estimate``, ``covariance`` and ``truth`` are in mm and deg; the standard
    error of combination v is sqrt(v' C v) (for OLS: sigma / its singular value)."""
    h = np.asarray(h_shown, dtype=float)
    _, s, vt = np.linalg.svd(h, full_matrices=False)
    largest = np.argmax(np.abs(vt), axis=1)
    vt = vt * np.sign(vt[np.arange(len(vt)), largest])[:, None]
    std = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", vt, np.asarray(covariance), vt), 0.0))
    order = np.argsort(std, kind="stable")
    vt, s, std = vt[order], s[order], std[order]
    return Combinations(
        names=list(names),
        directions=vt,
        estimate=vt @ np.asarray(estimate, dtype=float),
        std=std,
        truth=vt @ np.asarray(truth, dtype=float),
        rms_per_unit_mm=s / np.sqrt(h.shape[0]) * 1e3,
        bound=float(bound),
    )


def drawn_bound(truth_random: dict[str, Any] | None, fallback: float) -> float:
    """The largest half-range the source errors were drawn in (mm or deg; [truth.random]),
    or ``fallback`` when the truth was not drawn."""
    keys = ("translation_mm", "rotation_deg", "encoder_mm", "encoder_deg")
    values = [float(truth_random[k]) for k in keys if truth_random and k in truth_random]
    return max(values) if values else float(fallback)


def summary_entry(c: Combinations, sigma_mm: float, n_readings: int) -> dict[str, Any]:
    """The numbers the figure's and the report's sentence are made of."""
    bad = ~c.readable
    return {
        "n": len(c.std),
        "n_readable": int(np.sum(c.readable)),
        "bound": c.bound,
        "tracker_sigma_mm": sigma_mm,
        "n_reading_coordinates": n_readings,
        "unreadable_std": [float(c.std[bad].min()), float(c.std[bad].max())] if bad.any() else [],
        "unreadable_rms_per_unit_mm": float(c.rms_per_unit_mm[bad].max()) if bad.any() else None,
        "unreadable_members": c.unreadable_members(),
        "readable_largest_deviation": float(
            np.max(np.abs(c.estimate - c.truth)[c.readable], initial=0.0)
        ),
        "readable_largest_std": float(np.max(c.std[c.readable], initial=0.0)),
    }


def sentence(entry: dict[str, Any]) -> str:
    """Why the estimates of some parameters cannot be read, from the summary's numbers."""
    n, ok = entry["n"], entry["n_readable"]
    head = (
        f"The fine plan's readings fix {ok} of the {n} combinations of the kept parameters "
        f"(standard errors up to {entry['readable_largest_std']:.2g} mm or deg; the estimate "
        f"lies within {entry['readable_largest_deviation']:.2g} of the truth as the plan reads "
        "it)"
    )
    if ok == n:
        return head + ": every kept parameter can be read."
    lo, hi = entry["unreadable_std"]
    members = entry["unreadable_members"]
    big = entry.get("largest_member_estimate")
    largest = f" (up to {big:.3g} mm or deg)" if big is not None else ""
    return (
        head + f". The other {n - ok} move the {entry['n_reading_coordinates']} reading "
        f"coordinates by at most {entry['unreadable_rms_per_unit_mm']:.2g} mm RMS per mm (or "
        f"deg) of the combination, under the tracker's {entry['tracker_sigma_mm']:.3g} mm "
        f"noise: they are read only to {lo:.2g}-{hi:.2g} mm or deg (1 std), wider than the "
        f"+-{entry['bound']:.3g} the errors were drawn in. Their members "
        f"({', '.join(members)}) cannot be read one by one: their estimates{largest} are "
        "that noise and whatever the linear geometric model lacks, in directions the "
        "readings hardly see."
    )


@dataclass(frozen=True)
class PlanReading:
    """One estimator's kept parameters (mm and deg) and their combinations."""

    combinations: Combinations
    estimate: np.ndarray
    std: np.ndarray
    truth: np.ndarray
    summary: dict[str, Any]


def plan_readings(bench: Any, cal: Any, labels: list[str]) -> dict[str, PlanReading]:
    """The combinations of each of ``labels``' estimates, with the truth as the plan reads it:
    the kept parameters that fit, without noise, the readings the truth's geometry gives at
    the fine plan's commands (the twin side's knowledge; no noise drawn, no pose measured)."""
    from calib.two_step import nominal_targets
    from scenarios.studies.liu_vs_ols.noise import display_scale
    from twin.kinematics import forward_batch, one_blas_thread

    problem, params = cal.problem, bench.machine.params
    shown = display_scale(params, problem.columns)
    h_shown = problem.h / shown
    with one_blas_thread():
        clean = forward_batch(bench.machine.truth, cal.fine_commands).targets
        coarse_mech = bench.model.mechanism(cal.coarse.values)
        dp_clean = (clean - nominal_targets(coarse_mech, cal.fine_poses)).reshape(-1)
        truth = np.linalg.lstsq(h_shown, dp_clean, rcond=None)[0]
    names = [params.names[k] for k in problem.columns]
    random = bench.scenario.section("truth").get("random")
    sigma_mm = bench.sigma_m * 1e3
    out = {}
    for label in labels:
        est = cal.estimates[label][0]
        x, cov = est.x * shown, est.covariance * np.outer(shown, shown)
        with one_blas_thread():
            c = plan_combinations(
                h_shown, x, cov, truth, drawn_bound(random, float(np.max(np.abs(truth)))), names
            )
        entry = summary_entry(c, sigma_mm, h_shown.shape[0])
        members = [names.index(n) for n in entry["unreadable_members"]]
        entry["largest_member_estimate"] = float(np.max(np.abs(x[members]), initial=0.0))
        out[label] = PlanReading(c, x, np.sqrt(np.diag(cov)), truth, entry)
    return out
