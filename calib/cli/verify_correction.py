"""``verify`` of a result that carries a residual correction: the error with it, the poses
outside the calibrated region (uncorrected, listed) and its predictive std per pose."""

from __future__ import annotations

import numpy as np

from calib.correction import corrected_targets, correction_in, stats
from calib.data import select_set
from calib.fit import bind_dataset


def with_correction(model, loaded, dataset, set_name: str | None, after: dict) -> dict | None:
    """Score the readings of ``set_name`` with the result's correction added to the
    identified model's prediction (``model``'s state already bound to these readings by the
    verification); print it beside ``after`` (the verification's 'after' stats) and return
    the verification file's ``residual_correction`` block. None without a correction."""
    scored = correction_scores(model, loaded, dataset, set_name)
    if scored is None:
        return None
    s, pred, picked = scored
    e_len = len(pred["inside"])
    outside = [int(p) for p in np.asarray(picked.pose_ids)[~pred["inside"]]]
    std = pred["std"] * 1e3
    print(
        f"with the residual correction: 3D position error per reading RMS {s['rms_mm']:.4f} mm, "
        f"mean {s['mean_mm']:.4f} mm, max {s['max_mm']:.4f} mm (without: RMS "
        f"{after['rms_mm']:.4f}, max {after['max_mm']:.4f} mm)"
    )
    print(
        f"  {len(outside)} of {e_len} pose(s) outside the calibrated region, uncorrected"
        + (f": pose_id {', '.join(map(str, outside[:20]))}" if outside else "")
        + (" ..." if len(outside) > 20 else "")
    )
    inside = pred["inside"]
    if inside.any():
        print(
            f"  predictive std of the correction per corrected pose: median "
            f"{np.median(std[inside]):.4f}, max {np.max(std[inside]):.4f} mm per coordinate"
        )
    return {
        **s,
        "outside_calibrated_region": outside,
        "per_pose": [
            {"pose_id": int(p), "inside": bool(i), "std_mm_per_coordinate": float(d)}
            for p, i, d in zip(picked.pose_ids, inside, std, strict=True)
        ],
    }


def correction_scores(model, loaded, dataset, set_name: str | None):
    """The 3D error per reading of the rows of ``set_name`` with the result's correction
    added to the identified model's prediction (``model``'s state bound to these readings):
    (its stats, the correction's prediction, the rows scored); None without a correction."""
    corr = correction_in(loaded.data, model, str(loaded.path))
    if corr is None:
        return None
    picked, _ = select_set(dataset, set_name, "verification")
    obs = bind_dataset(model.nominal, picked)
    values = loaded.values_for(model.params)
    pred = corrected_targets(corr, model, values, obs.commands)
    measured = obs.measured
    if loaded.registration is not None:
        measured = loaded.registration.to_base(measured)
    e = (measured - pred["targets"]).reshape(len(measured), -1)
    return stats(e), pred, picked
