"""What ``identify --with`` of the diagnosis delivers, as ``diagnose`` reports it.

The diagnosis ranks its candidates by fits linearised at the geometric estimate: fast enough
to cross-validate every candidate and shape, but no model a user can take away. The figure
it reports for the effect it names is the one ``identify --with D.json`` then ``verify`` on
the same test rows reach: the same library function fits the diagnosis file's content
(calib.loop.fit_with_diagnosis: the geometry identify keeps, nonlinear, outliers and weak
directions as identify treats them, from the geometric fit's estimate, the residual
correction held when offered), and verify's own functions score it. It costs one fit of
geometry and effect (and, with a correction, one geometric fit of the readings less it).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from calib.cli.common import fit_options
from calib.cli.verify_correction import correction_scores
from calib.data import Dataset, read_dataset, result_from_content, result_text
from calib.exceptions import CalibError
from calib.fit import CalibrationRun, model_from_files, verify_result
from calib.loop import fit_with_diagnosis, model_for_result, with_result_content
from common.atomic_files import json_text

# the fit the reported figure comes from, as the printout and the file say it
FIT = "identify --with's fit"


def identify_with_scores(
    args: argparse.Namespace,
    geometric: CalibrationRun,
    effect: dict[str, Any],
    correction: dict[str, Any] | None,
    scored: tuple[Dataset, str | None],
) -> dict[str, Any] | None:
    """``identify --with`` of the diagnosis file whose ``effect`` block and residual
    ``correction`` (its dict, or None) are these, on ``args``' data and set with identify's
    default flags (``geometric``: diagnose's geometric fit, the same fit identify starts
    from), scored as ``verify`` scores the rows ``scored`` (a dataset, a set name):
    ``after`` and ``with_correction`` (3D per reading, mm), or ``failed`` (why). None when
    the effect adds no parameter (identify --with would refuse it, saying why)."""
    if not effect.get("added_parameters"):
        return None
    content: dict[str, Any] = {"effect": effect}
    if correction is not None:
        content["residual_correction"] = correction
    diagnosis = json.loads(json_text(content))  # as identify reads it from the file
    where = str(args.out) if args.out else "the diagnosis"
    base = model_from_files(args.model, args.errors)
    dataset = read_dataset(args.data, expected_model=base.nominal.name)
    said: list[str] = []
    try:
        run = fit_with_diagnosis(
            base, dataset, diagnosis, where, fit_options(args), geometric, said.append
        )
        files = (args.model, args.errors, args.data)
        result = with_result_content(run, base, files, where, diagnosis)
        loaded = result_from_content(json.loads(result_text(result)), Path(where))
        model = model_for_result(model_from_files(args.model, args.errors), loaded.data)
        ds, set_name = scored
        v, _ = verify_result(model, loaded, ds, set_name)
        with_corr = correction_scores(model, loaded, ds, set_name)
    except CalibError as exc:  # a fit that fails, values the verification cannot use
        return {"failed": str(exc)}
    keys = ("rms_mm", "mean_mm", "max_mm")
    return {
        "fit": FIT,
        "exit_code": run.verdict.exit_code,
        "after": {k: v.after.as_dict()[k] for k in keys},
        "with_correction": None if with_corr is None else {k: with_corr[0][k] for k in keys},
    }


def scores_sentence(got: dict[str, Any]) -> str:
    """The printed line of :func:`identify_with_scores`' numbers: the figure the diagnosis
    reports for the effect it names."""
    if "failed" in got:
        return f"{FIT} of the named effect failed: {got['failed']}"
    a, c = got["after"], got["with_correction"]
    corr = "" if c is None else f"; with the residual correction RMS {c['rms_mm']:.4f} mm"
    return (
        f"test after : 3D position error per reading RMS {a['rms_mm']:.4f} mm, mean "
        f"{a['mean_mm']:.4f} mm, max {a['max_mm']:.4f} mm{corr} ({FIT} of the named effect, "
        "what `identify --with` and `verify` of the diagnosis file reach: nonlinear, the "
        f"geometry identify keeps, from the geometric fit's estimate"
        f"{', the residual correction held' if c else ''})"
    )
