"""``pkm-calib diagnose``: what geometry leaves, tested for the effects it lacks."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from calib.cli.common import print_verdict, run_fit
from calib.data import Dataset, DatasetError, read_dataset, select_set, subset
from calib.fit import ASSUMED_SIGMA_MM, EXIT_OK, Accuracy, CalibrationRun, noise_rule, rejected_rows
from calib.loop import effect_content
from common.atomic_files import json_text
from common.write_set import write_files

# the noise source diagnose states when nothing gave one: identify's own assumption
ASSUMED_NOISE = (
    f"assumed {ASSUMED_SIGMA_MM:g} mm, as identify assumes: no --sigma-mm, no sidecar "
    "tracker.sigma_mm, no repeat readings"
)


def _held_out_rows(
    args: argparse.Namespace, fitted_ids: np.ndarray, data: Dataset
) -> tuple[object, str, tuple[object, str | None]] | None:
    """The held-out rows for the diagnosis, a sentence saying which, and how ``verify``
    scores them (a dataset and a set name): ``--test-set NAME`` of ``--test FILE`` (or of
    ``--data``); ``--test FILE`` alone: its 'test' rows if it has any, else the rows of the
    ``--data`` file not fitted, else all of FILE. None without either option. ``data``: the
    ``--data`` file, read once (a campaign's file takes a second to read)."""
    if not args.test and not args.test_set:
        return None
    same = not args.test or Path(args.test).resolve() == Path(args.data).resolve()
    path = args.data if same else args.test
    ds = data if same else read_dataset(path, expected_model=data.model)
    sets = [str(s) for s in ds.sets]
    view: tuple[object, str | None] = (ds, None)
    if args.test_set:
        picked, sentence = select_set(ds, args.test_set, "the diagnosis's test")
        view = (ds, args.test_set)
    elif "test" in sets:
        picked, sentence = select_set(ds, "test", "the diagnosis's test")
        view = (ds, "test")
    elif same:
        fitted = {int(p) for p in fitted_ids.tolist()}
        mask = np.array([int(p) not in fitted for p in ds.pose_ids.tolist()])
        if not mask.any():
            raise DatasetError(
                f"{path}: every pose was fitted; mark held-out rows in the set column and "
                "give --test-set NAME, or give --test FILE with other poses"
            )
        picked = subset(ds, mask)
        view = (picked, None)
        sentence = f"{picked.n_poses} poses of {path} not fitted used as the diagnosis's test"
    else:
        picked, sentence = ds, f"all {ds.n_poses} poses of {path} used as the diagnosis's test"
    if same:
        fitted = {int(p) for p in fitted_ids.tolist()}
        both = sorted(fitted & {int(p) for p in picked.pose_ids.tolist()})
        if both:
            raise DatasetError(
                f"{len(both)} test pose(s) were also fitted (pose_id {both[0]}"
                f"{' ...' if len(both) > 1 else ''}): a held-out set must hold other poses"
            )
    return picked, sentence, view


def _diagnosis_test_set(held: tuple[object, str] | None, run: CalibrationRun):
    """The held-out rows (:func:`_held_out_rows`) as a TestSet in the base frame (through the
    calibration's registration for tracker-frame data), and the sentence saying which;
    (None, "")."""
    from calib.diagnosis import TestSet
    from calib.fit import bind_dataset

    if held is None:
        return None, ""
    ds, sentence, _ = held
    obs = bind_dataset(run.model.nominal, ds)
    if obs.frame != run.obs.frame:
        raise DatasetError(
            f"the test data is in the '{obs.frame}' frame but the calibration data in "
            f"'{run.obs.frame}'"
        )
    measured = obs.measured
    if run.result.registration is not None:
        measured = run.result.registration.to_base(measured)
    test = TestSet(
        obs.commands,
        measured,
        None if ds.order is None else np.asarray(ds.order),
        None if ds.time_s is None else np.asarray(ds.time_s),
    )
    return test, sentence


def _checked_inputs(args: argparse.Namespace) -> tuple[tuple | None, Accuracy, Dataset]:
    """What diagnose needs besides the fit, checked before it: the held-out rows, the
    noise level (identify's rule: declared, else the repeats, else the same assumption) and
    the ``--data`` file as read."""
    data = read_dataset(args.data)
    picked, _ = select_set(data, args.set, "calibration")
    held = _held_out_rows(args, picked.pose_ids, data)
    return held, noise_rule(args.sigma_mm, picked), data


def cmd_diagnose(args: argparse.Namespace) -> int:
    from calib.diagnosis import diagnose

    held, accuracy, data = _checked_inputs(args)  # before the fit: a wrong input costs no fit
    run = run_fit(args, data)
    if isinstance(run, int):
        return run
    print(run.selection)
    if not run.verdict.ok:  # only what a user must fix: data errors, no convergence
        cause = (
            "it did not converge: give it more iterations (--max-iterations N)"
            if run.verdict.status == "not_converged"
            else "fix the data first"
        )
        print(
            f"the geometric fit the diagnosis starts from is not usable; {cause}",
            file=sys.stderr,
        )
        print_verdict(run.verdict)
        return run.verdict.exit_code
    print(f"geometric fit: {run.verdict.message}")
    head = (run.dataset.tracker or {}).get("position_mm")
    obs = run.obs
    if run.result.registration is not None:  # the diagnosis works in the base frame
        obs = replace(obs, measured=run.result.registration.to_base(obs.measured), frame="base")
    test, test_sentence = _diagnosis_test_set(held, run)
    if test_sentence:
        print(test_sentence)
    elif "test" in {str(x) for x in data.sets} and args.set != "test":
        print("note: the data's 'test' rows were not used; --test-set test holds them out")
    typed = None if accuracy.source == "repeats" else accuracy.sigma_mm
    ds = run.dataset
    diag = diagnose(
        run.model,
        obs,
        run.result,
        None if typed is None else typed * 1e-3,
        order=ds.order,
        time_s=ds.time_s,
        repeat_std_m=ds.repeat_std if ds.n_repeats > 1 else None,
        n_repeats=ds.n_repeats,
        tracker_position_m=None if head is None else np.asarray(head, dtype=float) * 1e-3,
        test=test,
        registration=run.result.registration is not None,
        sigma_source="typed" if accuracy.source != "assumed" else ASSUMED_NOISE,
    )
    noise = diag.noise.as_dict() if diag.noise is not None else {}
    print(
        f"geometric residual {diag.residual_rms_mm:.4f} mm RMS per coordinate; noise "
        f"{diag.noise_floor_rms_mm:.4f} mm per coordinate ({noise.get('source', 'typed')}); "
        f"chi-square p = {diag.chi2_p_value:.3g}"
    )
    print(f"diagnosis: {diag.chosen} ({diag.reason})")
    for note in diag.notes:
        print(f"  note: {note}")
    for name, entry in diag.effect_parameters.items():
        for pname, v in entry.items():
            if v.get("determined") is False:
                print(f"  {name}: {pname} {v['why']}")
                continue
            std = "" if v["std"] is None else f" +- {v['std']:.3g}"
            value = v["value"] if isinstance(v["value"], str) else f"{v['value']:.4g}"
            print(f"  {name}: {pname} = {value}{std} {v['unit']}")
    for name, score in diag.scores.items():
        tail = "" if score.test_rms_mm is None else f", test RMS {score.test_rms_mm:.5f} mm (3D)"
        refused = f"  REFUSED: {score.refused}" if score.refused else ""
        print(
            f"  {name:24s} held-out RMS blocked {score.heldout_blocked_mm:.5f} / random "
            f"{score.heldout_random_mm:.5f} mm{tail}{refused}"
        )
    effect = effect_content(
        run.model, diag.chosen, diag.effect_parameters, diag.time_unit, diag.time_origin
    )
    refit = effect["added_parameters"] and diag.test is not None and held is not None
    if diag.test is not None:
        ranked = " (the linearised fit that ranked the candidates)" if refit else ""
        for side in ("before", "after"):
            t = diag.test[side]
            label = "before" if side == "before" else f"after{ranked or ' '}"
            print(
                f"test {label}: 3D position error per reading RMS {t['rms_mm']:.4f} mm, "
                f"mean {t['mean_mm']:.4f} mm, max {t['max_mm']:.4f} mm"
            )
    from calib.cli.diagnose_correction import correction_stage
    from calib.cli.diagnose_refit import identify_with_scores, scores_sentence

    delivered: dict = {}

    def identify_with(correction: dict | None) -> dict | None:
        """identify --with of what the diagnosis writes (this correction), scored on the
        test rows as verify scores it; said, and kept for the file."""
        got = identify_with_scores(args, run, effect, correction, held[2]) if refit else None
        if got is not None:
            print(scores_sentence(got))
            delivered.update(got)
        return got

    added, figure = correction_stage(run, obs, diag, test, identify_with)
    if refit and not delivered:  # no correction stage ran
        identify_with(None)
    if args.out:
        out = Path(args.out)
        content = {
            "model": run.model.nominal.name,
            "residual": run.residual,
            "residual_rms_mm_per_coordinate": diag.residual_rms_mm,
            "noise_floor_rms_mm_per_coordinate": diag.noise_floor_rms_mm,
            "noise": noise,
            "chi2_p_value": diag.chi2_p_value,
            "diagnosed_effect": diag.chosen,
            "reason": diag.reason,
            "notes": list(diag.notes),
            "rejected": rejected_rows(run),
            "candidates": {n: s.heldout_rms_mm for n, s in diag.scores.items()},
            "heldout_rms_mm_per_coordinate": diag.heldout,
            "refused": {n: s.refused for n, s in diag.scores.items() if s.refused},
            "effect_parameters": diag.effect_parameters,
            "residual_structure": diag.structure_detail,
            "metric": "3D position error per reading |p_measured - p_model| (mm)",
            "effect": effect,
        }
        if diag.test is not None:
            content["test"] = {
                side: {k: diag.test[side][k] for k in ("rms_mm", "mean_mm", "max_mm")}
                for side in ("before", "after")
            }
            if "after" in delivered:  # the figure reported: what identify --with delivers
                lin = content["test"]["after"]
                content["test"].update(
                    after=delivered["after"],
                    after_fit=delivered["fit"],
                    after_linearised=lin,
                    with_correction=delivered["with_correction"],
                )
                content["reason"] += (
                    f"; {delivered['fit']}: test RMS {delivered['after']['rms_mm']:.4g} mm"
                )
        content.update(added)
        files: dict = figure(out) if added else {}
        if diag.plot is not None:
            from calib.diagnosis import save_diagnosis_png

            content["figure"] = str(out.with_suffix(".png"))
            files[out.with_suffix(".png")] = lambda tmp: save_diagnosis_png(diag, tmp)
        write_files({out: json_text(content), **files}, make_parents=True)  # both, or neither
    return EXIT_OK
