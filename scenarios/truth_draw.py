"""Seeded random truths: every source error drawn with a magnitude per kind."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenarios.config import Scenario
from twin.parameters import ParameterSet


@dataclass(frozen=True)
class TruthSpec:
    """Half-widths (uniform) or standard deviations (gaussian), in file units (mm, deg)."""

    distribution: str
    translation_mm: float
    rotation_deg: float
    encoder_mm: float
    encoder_deg: float

    @classmethod
    def from_scenario(cls, scenario: Scenario, key: str = "truth.random") -> TruthSpec:
        return cls(
            distribution=scenario.get(f"{key}.distribution", str, "uniform"),
            translation_mm=scenario.get(f"{key}.translation_mm", float),
            rotation_deg=scenario.get(f"{key}.rotation_deg", float, 0.0),
            encoder_mm=scenario.get(f"{key}.encoder_mm", float, 0.0),
            encoder_deg=scenario.get(f"{key}.encoder_deg", float, 0.0),
        )


def draw_truth(params: ParameterSet, spec: TruthSpec, rng: np.random.Generator) -> np.ndarray:
    """One value per parameter (SI), drawn by kind: translations, rotations, encoder offsets."""
    if spec.distribution not in ("uniform", "gaussian"):
        raise ValueError(
            f"truth distribution must be 'uniform' or 'gaussian', got {spec.distribution!r}"
        )
    shown = np.empty(len(params))
    for k, p in enumerate(params.parameters):
        if p.kind == "joint_zero":
            scale = spec.encoder_deg if params.is_angle[k] else spec.encoder_mm
        elif p.kind == "body_rot":
            scale = spec.rotation_deg
        else:
            scale = spec.translation_mm
        if spec.distribution == "uniform":
            shown[k] = rng.uniform(-scale, scale)
        else:
            shown[k] = rng.normal(0.0, scale)
    return params.from_display(shown)
