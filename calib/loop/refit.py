"""``identify --with``'s fit of a diagnosis, in one function that both commands call.

``identify --with D.json`` fits, to the readings, the geometry identify keeps (the error
model, or its fuller variant when identify keeps that: calib.fit.fuller_model) with the
parameters of the effect the diagnosis named, by the nonlinear fit identify runs (outliers
rejected, weakly determined directions kept at zero), from the geometric fit's estimate (the
effect's parameters at zero); with a residual correction in the file, the readings less the
correction are what it fits (calib.correction.held_dataset). ``diagnose`` ranks its
candidates by fast linearised fits; the figure it reports for the effect it names is this
fit's, scored as ``verify`` scores the result, so that what it reports is what
``identify --with`` delivers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from calib.correction.held import correction_in, held_dataset
from calib.data.dataset import Dataset
from calib.fit.model import CalibrationModel
from calib.fit.run_content import result_content
from calib.fit.workflow import CalibrationRun, calibrate
from calib.loop.effect_kinds import effect_block, extended_model, parameter_entry

Say = Callable[[str], None]


def fit_with_diagnosis(
    base: CalibrationModel,
    dataset: Dataset,
    diagnosis: dict[str, Any],
    where: str,
    options: dict[str, Any],
    geometric: CalibrationRun | None = None,
    say: Say = print,
) -> CalibrationRun:
    """``identify --with``: ``base`` (the error model) with the effect of the diagnosis
    file's content ``diagnosis`` (named ``where``) fitted to ``dataset`` with ``options``
    (calib.fit.calibrate's). ``geometric``: the geometric fit of ``base`` on ``dataset``
    with these options, when the caller has it (else it is run here; the gate
    ``max_ratio`` plays no part in it). What it does is said through ``say``."""
    correction = correction_in(diagnosis, base, where)
    block = effect_block(diagnosis, base, where, allow_empty=correction is not None)
    model = extended_model(base, block["added_parameters"], where)
    if correction is not None:  # the diagnosis's residual correction, held in the fit
        geo = geometric or calibrate(base, dataset, **{**options, "max_ratio": None})
        dataset, inside = held_dataset(
            dataset, correction, geo.model, geo.result.values, geo.result.registration
        )
        say(
            f"residual correction of {where} held: the readings less it at {inside} of "
            f"{dataset.n_poses} poses (the others outside the calibrated region), the geometry"
            " and any named effect refitted to what is left"
        )
        geometric = None  # the start is the geometric fit of what is left
    start = None
    if model.n_parameters > base.n_parameters:
        start, model = _geometric_start(
            base, model, dataset, options, diagnosis, where, geometric, say
        )
    return calibrate(model, dataset, start=start, **options)


def _geometric_start(
    base: CalibrationModel,
    model: CalibrationModel,
    dataset: Dataset,
    options: dict[str, Any],
    diagnosis: dict[str, Any],
    where: str,
    geometric: CalibrationRun | None,
    say: Say,
) -> tuple[np.ndarray | None, CalibrationModel]:
    """The start of a fit with a diagnosed effect: the geometric fit's estimate, where the
    diagnosis formed the effect's columns (an added parameter can move the readings there
    and not at the nominal model: a joint with the nominal reflector on its axis), the added
    parameters at zero; None (the nominal start) when the geometric fit is refused. And the
    model to fit: the geometric fit's own (the error model's fuller variant when identify
    kept it, calib.fit.fuller_model) with the effect's parameters."""
    geo = geometric or calibrate(base, dataset, **{**options, "max_ratio": None})
    if not geo.verdict.ok:
        return None, model
    if geo.model.n_parameters != base.n_parameters:  # the fuller geometry, and the effect
        added = effect_block(diagnosis, geo.model, where)["added_parameters"]
        model = extended_model(geo.model, added, where)
        names = ", ".join(geo.model.params.names[base.n_parameters :])
        say(f"the geometry as identify kept it: the error model and {names}")
    names = list(model.params.names)
    start = np.zeros(model.n_parameters)
    for name, value in zip(geo.result.names, geo.result.values, strict=True):
        start[names.index(name)] = value
    say(
        f"start: the geometric fit's estimate ({geo.residual['rms_mm']:.4f} mm RMS), the "
        f"{model.n_parameters - geo.model.n_parameters} added parameters at zero"
    )
    return start, model


def with_result_content(
    run: CalibrationRun,
    base: CalibrationModel,
    files: tuple[str, str, str],
    where: str,
    diagnosis: dict[str, Any],
) -> dict[str, Any]:
    """The result file ``identify --with`` writes of ``run`` (its fit of the diagnosis
    ``diagnosis``, named ``where``), ``files`` the model, error model and data paths: the
    fit, the parameters it added to ``base`` (what verify, compensate and export rebuild),
    and the residual correction it held."""
    content = result_content(run, *files)
    content["with"] = str(where)
    names = set(base.params.names)
    added = [parameter_entry(p) for p in run.model.params.parameters if p.name not in names]
    if added:
        content["added_parameters"] = added
    held = correction_in(diagnosis, run.model, where)
    if held is not None:
        content["residual_correction"] = held.to_dict(run.model.nominal.name)
    return content
