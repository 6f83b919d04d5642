"""``verify --iso9283``: ISO 9283 pose accuracy and repeatability before and after.

The readings' repeats at one commanded pose (the Dataset's ``repeat`` column, or poses with
identical commands) are the standard's attained poses; each side's command pose is its
model's prediction (calib.analysis.iso9283). The readings are in the frames the verification
used (the result's registration, or ``--register``'s). ``--out R.json`` writes R.json, R.csv
(one row per commanded pose and side) and R.png as one set.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from calib.analysis import (
    ORIENTATION_KEYS,
    POSITION_KEYS,
    STANDARD,
    IsoSide,
    group_commands,
    iso_side,
)
from calib.data import Dataset, DatasetError, subset
from calib.fit import CalibrationModel, Registration, Verification
from common.atomic_files import json_text
from common.write_set import write_files

DEFINITIONS = {
    "AP_P": "positional pose accuracy: distance from the command position to the barycentre "
    "of the attained positions",
    "AP_x, AP_y, AP_z": "barycentre minus command, per axis",
    "AP_a, AP_b, AP_c": "mean attained minus command rotation about x, y, z (roll, pitch, yaw)",
    "RP_l": "positional pose repeatability l_bar + 3 S_l (l_j: distance of attained pose j from "
    "the barycentre; S_l: their sample standard deviation, n - 1)",
    "RP_a, RP_b, RP_c": "orientation pose repeatability +-3 S_a (the half-width given)",
    "command pose": "the side's model prediction for the command: nominal (before), calibrated "
    "(after)",
    "position": "centroid of the pose's targets; orientation (three or more targets): rigid fit "
    "of the model's target pattern",
}


def _attained(reg: Registration | None, readings: np.ndarray) -> np.ndarray:
    return readings if reg is None else reg.to_base(readings)


def iso_report(
    model: CalibrationModel, values: np.ndarray, dataset: Dataset, v: Verification
) -> dict:
    """The ISO 9283 content of the poses ``v`` scored, before and after."""
    mech = model.nominal
    picked = subset(dataset, np.isin(dataset.pose_ids, v.pose_ids))
    ds = picked.reordered(mech.actuator_names, mech.target_names)
    p, t, r, _ = ds.readings.shape
    readings = np.swapaxes(np.asarray(ds.readings), 1, 2).reshape(p * r, t, 3)
    commands = np.repeat(np.asarray(ds.commands), r, axis=0)
    pose_ids = np.repeat(np.asarray(ds.pose_ids), r)
    groups = group_commands(commands)
    counts = np.bincount(groups)
    repeated = counts[groups] >= 2
    if not repeated.any():
        raise DatasetError(
            "--iso9283: no commanded pose is repeated; ISO 9283 needs several attained poses "
            "per command (the 'repeat' column, or poses with identical commands)"
        )
    keep = np.flatnonzero(repeated)
    groups = group_commands(commands[keep])
    local = mech.target_local() if t >= 3 else None
    fresh = CalibrationModel(mech, model.params)
    sides: dict[str, IsoSide] = {}
    for side, x, reg in (
        ("before", np.zeros(model.n_parameters), v.registration_before),
        ("after", np.asarray(values, dtype=float), v.registration_after),
    ):
        predicted = fresh.predict(x, commands[keep]).targets
        sides[side] = iso_side(_attained(reg, readings[keep]), predicted, groups, local)
    poses = []
    for g in range(int(groups.max()) + 1):
        ids = sorted({int(i) for i in pose_ids[keep][groups == g]})
        entry = {"pose": f"P{g + 1}", "pose_ids": ids}
        entry.update({s: sides[s].per_pose[g] for s in ("before", "after")})
        poses.append(entry)
    keys = ("AP_P_mm", "RP_l_mm") + (("AP_a_deg", "RP_a_deg") if local is not None else ())
    return {
        "standard": STANDARD,
        "definitions": DEFINITIONS,
        "n_commanded_poses": len(poses),
        "n_attained_poses": len(keep),
        "n_single_readings_left_out": int(len(readings) - len(keep)),
        "orientation": local is not None,
        "poses": poses,
        "worst": {s: {k: sides[s].worst(k) for k in keys} for s in ("before", "after")},
        "frame_note": v.note,
    }


def lines(report: dict) -> list[str]:
    """The printed lines, one per commanded pose, from the report's numbers."""
    out = [
        f"{report['standard']}: {report['n_commanded_poses']} commanded poses, "
        f"{report['n_attained_poses']} attained poses (before -> after)"
    ]
    if report["n_single_readings_left_out"]:
        out.append(
            f"{report['n_single_readings_left_out']} reading(s) of unrepeated commands left out"
        )
    for pose in report["poses"]:
        b, a = pose["before"], pose["after"]
        text = (
            f"  {pose['pose']} (n={a['n']}): AP_P {b['AP_P_mm']:.4f} -> {a['AP_P_mm']:.4f} mm, "
            f"RP_l {b['RP_l_mm']:.4f} -> {a['RP_l_mm']:.4f} mm"
        )
        if report["orientation"]:
            text += "; AP_a/b/c " + " ".join(
                f"{b[k]:+.4f}->{a[k]:+.4f}" for k in ("AP_a_deg", "AP_b_deg", "AP_c_deg")
            )
            text += " deg, RP_a/b/c " + " ".join(
                f"{a[k]:.4f}" for k in ("RP_a_deg", "RP_b_deg", "RP_c_deg")
            )
            text += " deg (after)"
        out.append(text)
    return out


def csv_text(report: dict) -> str:
    keys = ["n", *POSITION_KEYS] + (list(ORIENTATION_KEYS) if report["orientation"] else [])
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["pose", "side", *keys])
    for pose in report["poses"]:
        for side in ("before", "after"):
            writer.writerow([pose["pose"], side, *(pose[side][k] for k in keys)])
    return buf.getvalue()


def save_png(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [p["pose"] for p in report["poses"]]
    idx = np.arange(len(names))
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, key, title in zip(
        axes, ("AP_P_mm", "RP_l_mm"), ("pose accuracy AP_P", "pose repeatability RP_l"), strict=True
    ):
        for k, side in enumerate(("before", "after")):
            vals = [p[side][key] for p in report["poses"]]
            ax.bar(idx + (k - 0.5) * 0.4, vals, 0.4, label=f"{side} (max {max(vals):.4f} mm)")
        ax.set_xticks(idx, names)
        ax.set_ylabel(f"{key[:-3]} (mm)")
        ax.set_title(f"ISO 9283 {title}")
        ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        fig.savefig(path, format="png", dpi=110)
    finally:
        plt.close(fig)


def run(
    model: CalibrationModel,
    values: np.ndarray,
    dataset: Dataset,
    v: Verification,
    out: str | None,
    content: dict,
) -> None:
    """Print the ISO 9283 report of ``v``'s poses and, with ``out``, write its set."""
    report = iso_report(model, values, dataset, v)
    for line in lines(report):
        print(line)
    if out:
        path = Path(out)
        write_files(
            {
                path: json_text({**content, **report}),
                path.with_suffix(".csv"): csv_text(report),
                path.with_suffix(".png"): lambda tmp: save_png(report, tmp),
            },
            make_parents=True,
        )
        print(f"wrote {path}, {path.with_suffix('.csv')} and {path.with_suffix('.png')}")
