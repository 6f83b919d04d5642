"""Shared helpers of the compensate / export tests: result files made from known values."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.data.result_file import write_result
from calib.fit.registration import Registration
from twin.parameters import Parameter, ParameterSet

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"


def plausible_values(params: ParameterSet, rng: np.random.Generator) -> np.ndarray:
    """Errors of a built machine: 0.3 mm, 0.05 deg (uniform), SI."""
    return np.where(
        params.is_angle,
        np.radians(rng.uniform(-0.05, 0.05, len(params))),
        rng.uniform(-3e-4, 3e-4, len(params)),
    )


def result_file(
    path: Path,
    model: str,
    params: ParameterSet,
    values: np.ndarray,
    registration: Registration | None = None,
    added: list[Parameter] | None = None,
) -> Path:
    """A result file as ``calib identify --out`` writes it, holding ``values`` (SI) of
    ``params``; ``added``: those of them that ``identify --with`` added to the error model."""
    shown = params.to_display(values)
    units = params.display_units()
    content = {
        "model": model,
        "frame": "base" if registration is None else "tracker",
        "parameters": {
            n: {"value": float(v), "unit": u, "status": "estimated"}
            for n, v, u in zip(params.names, shown, units, strict=True)
        },
        "registration": None if registration is None else registration.as_dict(),
    }
    if added:
        content["added_parameters"] = [
            {"name": p.name, "kind": p.kind, "element": p.element, "axis": list(p.axis)}
            for p in added
        ]
    return write_result(path, content)
