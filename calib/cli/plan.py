"""``pkm-calib plan``: which poses to measure, in what order, and what they will give.

    pkm-calib plan --model M.xml --errors E.toml --n N --out program.csv
                         [--n-test K] [--candidates FILE [--set NAME] | --n-candidates C]
                         [--margin F] [--floor-z MM] [--tracker-at X,Y,Z [--acceptance-deg A]]
                         [--criterion d_optimal|paper] [--seed S]
                         [--predict [--predict-n N1,N2,...] [--draws D] [--sigma-mm S]]

Candidates are random reachable poses of the workspace (or the poses of ``--candidates``, a
Dataset or a program CSV of poses known to be safe, the rows of ``--set``). Those within the
joint and stroke limits (a ``--margin`` fraction of each range kept free), free of collisions
between the machine's geoms and of the floor, and, with ``--tracker-at`` (mm, base frame),
whose reflectors the tracker sees (line of sight, incidence within ``--acceptance-deg``; the
reflector's normal taken as the target site's z axis) are feasible. Of them N calibration
poses maximise the observability of the identifiable parameters (D-optimal exchange; the
second paper's greedy condition-number selection with ``--criterion paper``) and K test poses
cover the workspace. The program CSV (``pose_id,set,cmd:<actuator>...,dir:<actuator>...``, mm
and deg, in the order to run) keeps the travel short, interleaves test with calibration poses
and approaches each actuator from both sides. ``--predict``: the twin simulates the campaign
for truths drawn from the error model's ranges and tracker noise ``--sigma-mm``, and reports
the held-out 3D error (median, 90th percentile) against N for the plan and for random poses
(program.json, program.png). Measure the program, then ``identify --set calibration`` and
``verify --set test``. Exit 0, or 2 with the cause.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from calib.cli.common import positive_float, positive_int, sigma_float
from calib.fit import EXIT_OK, model_from_files
from calib.plan import (
    Rules,
    accuracy_curve,
    file_candidates,
    make_plan,
    program_text,
    save_curve_png,
    workspace_candidates,
)
from common.atomic_files import json_text
from common.write_set import write_files

DEFAULT_SIGMA_MM = 0.05  # identify's default tracker accuracy when none is declared


def _point_mm(text: str) -> np.ndarray:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y,z in mm, got {text!r}") from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected three finite numbers x,y,z (mm), got {text!r}")
    return np.array(values) * 1e-3


def _counts(text: str) -> list[int]:
    try:
        values = sorted({int(v) for v in text.split(",")})
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected whole numbers N1,N2,..., got {text!r}"
        ) from None
    if not values or values[0] < 1:
        raise argparse.ArgumentTypeError(f"expected whole numbers >= 1, got {text!r}")
    return values


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (0.0 <= value < 0.5):
        raise argparse.ArgumentTypeError(f"expected a fraction in [0, 0.5), got {text!r}")
    return value


def _angle(text: str) -> float:
    value = positive_float(text)
    if value > 90:
        raise argparse.ArgumentTypeError(f"an acceptance angle is at most 90 deg, got {text!r}")
    return value


def _floor_mm(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite height in mm, got {text!r}")
    return value


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan",
        help="choose, order and predict the poses of a measurement campaign",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", required=True, help="nominal MJCF of the machine")
    p.add_argument("--errors", required=True, help="error model (TOML [[parameter]] list)")
    p.add_argument("--n", required=True, type=positive_int, help="calibration poses to plan")
    p.add_argument("--out", required=True, help="the program CSV to write (+ .json beside it)")
    p.add_argument("--n-test", type=int, help="test poses to add (default: N/4, at least 5)")
    p.add_argument("--candidates", help="a Dataset or program CSV of poses known to be safe")
    p.add_argument("--set", help="use the rows of this set of --candidates")
    p.add_argument(
        "--n-candidates",
        type=positive_int,
        default=2000,
        help="random workspace poses to draw (without --candidates; default 2000)",
    )
    p.add_argument(
        "--margin",
        type=_fraction,
        default=0.02,
        help="fraction of each actuator's range kept free at both ends (default 0.02)",
    )
    p.add_argument("--floor-z", type=_floor_mm, help="floor height (mm, base frame)")
    p.add_argument("--tracker-at", type=_point_mm, help="tracker head x,y,z (mm, base frame)")
    p.add_argument(
        "--acceptance-deg",
        type=_angle,
        default=30.0,
        help="reflector acceptance angle (deg; default 30, an SMR)",
    )
    p.add_argument("--criterion", choices=("d_optimal", "paper"), default="d_optimal")
    p.add_argument("--seed", type=int, default=0, help="seed of the random draws (default 0)")
    p.add_argument("--predict", action="store_true", help="predict the accuracy against N")
    p.add_argument("--predict-n", type=_counts, help="the N values (default: N/3, 2N/3, N)")
    p.add_argument("--draws", type=positive_int, default=5, help="truths drawn (default 5)")
    p.add_argument(
        "--sigma-mm",
        type=sigma_float,
        default=DEFAULT_SIGMA_MM,
        help=f"tracker noise per coordinate (mm; default {DEFAULT_SIGMA_MM})",
    )
    p.add_argument(
        "--truth-scale",
        type=positive_float,
        default=1.0,
        help="truths drawn within this many times the physical ranges (default 1: 1 mm, 0.1 deg)",
    )


def _n_test(args: argparse.Namespace) -> int:
    if args.n_test is None:
        return max(5, args.n // 4)
    if args.n_test < 0:
        raise ValueError(f"--n-test must be >= 0, got {args.n_test}")
    return args.n_test


def _default_counts(n: int, plan) -> list[int]:
    """N/3, 2N/3 and N, none below 1.5 times the fewest poses that give as many equations
    as the directions to identify (below that the outlier check has too few spare rows)."""
    rows, rank = plan.blocks.shape[1:]
    least = min(n, math.ceil(1.5 * rank / rows))
    return sorted({max(least, n // 3), max(least, 2 * n // 3), n})


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if args.candidates and out.exists() and out.resolve() == Path(args.candidates).resolve():
        raise ValueError(f"--out {out} would overwrite the candidates file")
    if args.set and not args.candidates:
        raise ValueError("--set selects rows of --candidates; give --candidates FILE")
    model = model_from_files(args.model, args.errors)
    mech = model.nominal
    rng = np.random.default_rng(args.seed)
    if args.candidates:
        cands = file_candidates(args.candidates, mech, args.set)
    else:
        cands = workspace_candidates(mech, args.n_candidates, rng)
    rules = Rules(
        margin=args.margin,
        floor_z_m=None if args.floor_z is None else args.floor_z * 1e-3,
        tracker_m=args.tracker_at,
        acceptance_deg=args.acceptance_deg,
    )
    plan = make_plan(model, cands, rules, args.n, _n_test(args), args.criterion, args.seed)
    print(f"candidates: {cands.source}")
    print(plan.feasibility.summary())
    floor = plan.feasibility.floor_z_m
    print("floor: " + ("none checked" if floor is None else f"z = {floor * 1e3:.1f} mm"))
    what = "log det of the scaled information" if args.criterion == "d_optimal" else "condition"
    print(
        f"{len(plan.calibration)} calibration poses ({args.criterion}: {what} "
        f"{plan.index_value:.4g} over the {plan.identified_directions} directions the "
        f"candidates identify of {model.n_parameters} parameters), {len(plan.test)} test poses"
    )
    o = plan.order
    print(
        f"order: travel {o.travel:.2f} range-widths (as selected: {o.travel_unordered:.2f}); "
        + ", ".join(
            f"{a} {int((d > 0).sum())} up/{int((d < 0).sum())} down"
            for a, d in zip(mech.actuator_names, o.directions.T, strict=True)
        )
    )
    content = {
        "model": str(args.model),
        "errors": str(args.errors),
        "candidates": cands.source,
        "feasibility": plan.feasibility.summary(),
        "criterion": args.criterion,
        "index_value": plan.index_value,
        "identified_directions": plan.identified_directions,
        "n_calibration": len(plan.calibration),
        "n_test": len(plan.test),
        "travel_range_widths": o.travel,
        "travel_as_selected": o.travel_unordered,
        "pose_ids": plan.labels,
        "sets": [str(s) for s in plan.sets],
    }
    files: dict = {out: program_text(mech, plan)}
    if args.predict:
        counts = args.predict_n or _default_counts(args.n, plan)
        curve = accuracy_curve(
            model, plan, counts, args.sigma_mm * 1e-3, args.draws, args.seed, args.truth_scale
        )
        rows = [p.stats() for p in curve]
        content["prediction"] = {
            "sigma_mm": args.sigma_mm,
            "draws": args.draws,
            "truth_scale": args.truth_scale,
            "curve": rows,
        }
        print(
            f"predicted held-out 3D error ({args.draws} truths within {args.truth_scale:g}x the "
            f"physical ranges, noise {args.sigma_mm:g} mm; readings against the identified "
            "model as verify scores them, mean +- std over the draws; beside, the model's own "
            "error against the drawn truth):"
        )
        for r in rows:
            print(
                f"  N={r['n']:4d} {r['kind']:6s}: median {r['median_mm']:.4f} +- "
                f"{r['median_std_mm']:.4f} mm, 90th pct {r['p90_mm']:.4f} +- "
                f"{r['p90_std_mm']:.4f} mm (the model's own: median {r['model_median_mm']:.4f}, "
                f"90th pct {r['model_p90_mm']:.4f} mm)"
                + (f"; {r['failed']} fit(s) failed" if r["failed"] else "")
            )
        title = f"{mech.name}: predicted held-out error, {args.draws} drawn truths"
        files[out.with_suffix(".png")] = lambda tmp: save_curve_png(curve, tmp, title)
    files[out.with_suffix(".json")] = json_text(content)
    write_files(files, make_parents=True)
    print("wrote " + ", ".join(str(p) for p in files))
    return EXIT_OK
