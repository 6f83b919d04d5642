"""``diagnose``'s last stage: the residual correction after the named effects, and the table
(and figure) of the share of the error each stage removed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.correction import (
    feature_names,
    fit_and_judge,
    pose_features,
    save_stages_png,
    stage_table,
    stats,
    table_lines,
)


def correction_stage(run, obs, diag, test, identify_with=None) -> tuple[dict, dict]:
    """Fit and judge the correction on what ``diag`` left, print its verdict and the stage
    table; returns the diagnosis file's additions and the figure to write (path -> writer),
    keyed by the file's stem later (``figure``: a function of the out path).
    ``identify_with``: called with the correction's dict (None when not offered), it returns
    what identify --with of the diagnosis file reaches on the test set (``after`` and
    ``with_correction`` stats, or None): the table's effect and correction rows then."""
    left = diag.leftover
    if left is None:
        return {}, {}
    mech = run.model.nominal
    arm = mech.is_serial
    names, units = feature_names(mech.actuator_names, tuple(mech.actuator_is_slide), arm)
    x = pose_features(left["commands"], left["position"] if arm else None)
    tdata = None
    if "test_residual" in left:
        xt = pose_features(left["test_commands"], left["test_position"] if arm else None)
        tdata = (xt, left["test_residual"])
    offer = fit_and_judge(
        x,
        left["residual"],
        left["complete"],
        left["labels"],
        diag.noise.sigma_m,
        names,
        units,
        tdata,
    )
    print(f"residual correction (kernel ridge over {', '.join(names)}): {offer.reason}")
    if offer.test_std_mm is not None:
        outside = np.flatnonzero(~offer.test_inside)
        print(
            f"  predictive std per test pose: median {np.median(offer.test_std_mm):.4f}, max "
            f"{np.max(offer.test_std_mm):.4f} mm per coordinate; {len(outside)} test pose(s) "
            "outside the calibrated region get no correction"
        )
    effect = diag.chosen if left.get("named") else "none named"
    got = None
    if identify_with is not None:
        got = identify_with(offer.correction.to_dict(mech.name) if offer.offered else None)
    if tdata is not None:
        nominal = _nominal_rms(run, test.commands, test.measured)
        rms = {
            "nominal": nominal,
            "geometry": stats(left["test_before"])["rms_mm"],
            "effect": stats(left["test_residual"])["rms_mm"],
            "correction": offer.numbers.get("test", {}).get("after", {}).get("rms_mm", 0.0),
        }
        where = "test set"
    else:
        geo = obs.measured - run.model.predict(run.result.values, obs.commands).targets
        complete = left["complete"]
        rms = {
            "nominal": _nominal_rms(run, obs.commands[complete], obs.measured[complete]),
            "geometry": stats(geo[complete].reshape(int(complete.sum()), -1))["rms_mm"],
            "effect": stats(left["residual"][complete])["rms_mm"],
            "correction": offer.numbers.get("cv", {}).get("after", {}).get("rms_mm", 0.0),
        }
        where = "calibration poses; the correction's held out in the cross-validation"
    if offer.correction is None:
        rms["correction"] = rms["effect"]
    if got is not None and "after" in got:  # what identify --with delivers, on the test set
        rms["effect"] = got["after"]["rms_mm"]
        rms["correction"] = (got["with_correction"] or got["after"])["rms_mm"]
        where += f"; the effect's and the correction's: {got['fit']}"
    if not offer.offered:
        where += "; the correction not offered"
    rows = stage_table(rms)
    for line in table_lines(rows, where, effect):
        print(line)
    content = {
        "residual_correction_verdict": offer.reason,
        "stages": {"where": where, "rows": rows},
    }
    if offer.offered:
        content["residual_correction"] = offer.correction.to_dict(mech.name)
    if offer.test_std_mm is not None:
        content["residual_correction_test"] = {
            "std_mm_per_coordinate": offer.test_std_mm.tolist(),
            "inside": offer.test_inside.tolist(),
        }
    title = f"each stage's share of the error ({where})"

    def figure(out: Path) -> dict:
        path = out.with_name(out.stem + ".stages.png")
        content["stages"]["figure"] = str(path)
        return {path: lambda tmp: save_stages_png(rows, tmp, title)}

    return content, figure


def _nominal_rms(run, commands: np.ndarray, measured_base: np.ndarray) -> float:
    """3D RMS of the nominal model's error on these base-frame readings."""
    nominal = run.model.predict(np.zeros(run.model.n_parameters), commands).targets
    return stats((measured_base - nominal).reshape(len(commands), -1))["rms_mm"]
