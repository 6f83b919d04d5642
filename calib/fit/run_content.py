"""What a calibration run says in its result file and printout: the rejected readings, the
result file's content, the prior and the weak-direction handling in words."""

from __future__ import annotations

from typing import Any

import numpy as np

from calib.fit.prior import physical_ranges
from calib.fit.probe_rows import probe_line
from calib.fit.regularisation import cut_label
from calib.fit.verify import probe_deg
from calib.fit.workflow import CalibrationRun


def probe_summary(run: CalibrationRun) -> str:
    """The line identify prints of 6-DoF readings (calib.fit.probe_rows.probe_line)."""
    res, obs = run.result, run.obs
    pred = run.model.predict(res.values, obs.commands)
    deg = probe_deg(run.model, res.values, pred.qpos, obs.rotations, res.registration)
    sigma_deg = float((run.dataset.tracker or {})["sigma_deg"])
    return probe_line(obs, run.verdict.accuracy.sigma_mm, sigma_deg, deg)


def rejected_rows(run: CalibrationRun) -> list[dict[str, Any]]:
    """The rejected readings by the dataset's pose_id and target name, residual in mm."""
    names = list(run.model.nominal.target_names)
    if run.obs.rotations is not None:  # a probe's orientation is a reading of its own
        oriented = np.isfinite(run.obs.rotations).all(axis=(0, 2, 3))
        names += [f"{n} (orientation)" for n, o in zip(names, oriented, strict=True) if o]
    return [
        {
            "pose_id": int(run.dataset.pose_ids[r.pose_index]),
            "target": names[r.target_index],
            "residual_mm": float(r.residual_m * 1e3),
        }
        for r in run.result.rejected
    ]


def result_content(run: CalibrationRun, model_path: str, errors_path: str, data_path: str):
    """Everything the result file holds (see calib.data.result_file)."""
    res, params = run.result, run.model.params
    shown = params.to_display(res.values)
    std = params.to_display(res.std_errors)
    units = params.display_units()
    reasons = res.report.unidentifiable
    parameters = {}
    for n, v, s, u, e in zip(res.names, shown, std, units, res.estimated, strict=True):
        entry: dict[str, Any] = {"value": float(v), "unit": u}
        if e:
            entry.update(status="estimated", std=float(s))
        else:
            entry.update(status="fixed", std=None, reason=reasons.get(n, "fixed"))
        parameters[n] = entry
    reg = None
    if res.registration is not None:
        reg = res.registration.as_dict(res.registration_std)
    return {
        "model": run.model.nominal.name,
        "model_file": str(model_path),
        "errors_file": str(errors_path),
        "data": str(data_path),
        "set": run.set_name,
        "selection": run.selection,
        "frame": run.obs.frame,
        "units": {"length": "mm", "angle": "deg"},
        "n_poses": run.dataset.n_poses,
        "masses_defaulted": run.model.nominal.masses_defaulted,
        "residual": run.residual,
        "residual_rms_mm": run.residual["rms_mm"],
        "metric": "3D position error per reading |p_measured - p_model| (mm)",
        "converged": res.converged,
        "convergence": res.convergence_message,
        "iterations": res.iterations,
        "verdict": run.verdict.as_dict(),
        "rejected": rejected_rows(run),
        "robust_scale_mm_per_coordinate": res.robust_scale_m * 1e3,
        "n_identifiable": res.report.n_identifiable,
        "unidentifiable": reasons,
        "redundant_with_registration": list(res.redundant_with_registration),
        "registration": reg,
        "prior": prior_content(run),
        "regularisation": regularisation_content(run),
        "residual_structure": run.structure,
        "weakly_identified": run.weak,
        "near_collinear_groups": run.groups,
        "correlations_above_0.9": run.correlations,
        "parameters": parameters,
        "fuller_model": None if run.fuller is None else run.fuller.as_dict(),
    }


def prior_content(run: CalibrationRun) -> dict[str, Any] | None:
    """The prior the kept fit used, in file units, and where its widths came from."""
    choice = run.regularisation
    if choice is None or choice.scale is None:
        return None
    ranges = physical_ranges(run.model.params, run.prior_spec)
    is_angle = np.asarray(run.model.params.is_angle, dtype=bool)
    is_length = ~is_angle & np.asarray(run.model.params.is_geometric, dtype=bool)
    length = float(ranges[is_length][0]) * 1e3 * choice.scale if is_length.any() else None
    angle = float(np.degrees(ranges[is_angle][0])) * choice.scale if is_angle.any() else None
    return {
        "length_mm": length,
        "angle_deg": angle,
        "source": "--prior-std" if run.prior_spec is not None else "cross-validated default",
        "weighed_against_mm_per_coordinate": choice.noise_sigma_m * 1e3,
    }


def regularisation_content(run: CalibrationRun) -> dict[str, Any]:
    """What the result file says of the weak directions: the choice and its numbers."""
    sub, choice = run.result.subspace, run.regularisation
    out: dict[str, Any] = {"text": regularisation_text(run)}
    if choice is not None:
        out.update(method="zero-mean prior (--prior-std)", **choice.as_dict())
    elif sub is not None:
        out.update(sub.as_dict())
    else:
        out["method"] = "plain least squares"
    return out


def regularisation_text(run: CalibrationRun) -> str:
    """What was regularised, in a sentence made of the run's numbers."""
    sub, choice = run.result.subspace, run.regularisation
    if choice is not None:  # the user's prior
        prior = prior_content(run) or {}
        widths = ", ".join(
            f"{v:.3g} {u}"
            for v, u in ((prior.get("length_mm"), "mm"), (prior.get("angle_deg"), "deg"))
            if v is not None
        )
        cv = choice.cv_rms_mm
        held = ""
        if "none" in cv and choice.label in cv:
            held = (
                f"; {choice.folds}-fold cross-validated 3D RMS {cv[choice.label]:.4f} mm with "
                f"it, {cv['none']:.4f} mm without"
            )
        return (
            f"prior (--prior-std): zero mean, {widths}, weighed against the data's residual "
            f"of {choice.noise_sigma_m * 1e3:.4f} mm per coordinate{held}"
        )
    if sub is None:
        return "plain least squares over every identifiable parameter"
    weak = (
        f"{sub.n_weak} direction(s) of the parameters the data determine worse than their "
        f"physical range (at the data's residual of {sub.noise_sigma_m * 1e3:.4f} mm per "
        "coordinate)"
    )
    cv = sub.cv_rms_mm
    if sub.cut is None:
        if not cv:
            return f"plain least squares: {weak}"
        return (
            f"plain least squares: {weak}; keeping them at zero would predict held-out poses "
            f"worse ({sub.folds}-fold cross-validated 3D RMS {cv['none']:.4f} mm plain, "
            + ", ".join(f"{k} {v:.4f} mm" for k, v in cv.items() if k != "none")
            + ")"
        )
    if sub.reason:
        return (
            f"regularised: {sub.n_frozen} of {weak} kept at zero (minimum norm), the rest "
            f"estimated: {sub.reason}"
        )
    return (
        f"regularised: {sub.n_frozen} of {weak} kept at zero (minimum norm), the rest "
        f"estimated; {sub.folds}-fold cross-validated 3D RMS {cv[cut_label(sub.cut)]:.4f} mm, "
        f"plain least squares {cv['none']:.4f} mm"
    )
