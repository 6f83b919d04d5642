"""What every study starts from: the nominal machine, its error model and the truth twin."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.model import CalibrationModel
from scenarios.config import Scenario
from scenarios.truth_draw import TruthSpec, draw_truth
from twin.mechanism import Mechanism
from twin.parameter_file import load_parameter_set, load_values
from twin.parameters import ParameterSet


@dataclass(frozen=True)
class ScenarioMachine:
    nominal: Mechanism
    params: ParameterSet
    truth_values: np.ndarray  # SI
    truth: Mechanism  # the nominal model with the truth injected: the twin side only

    def calibration_model(self) -> CalibrationModel:
        return CalibrationModel(self.nominal, self.params)


def load_machine(scenario: Scenario, rng: np.random.Generator) -> ScenarioMachine:
    """Model and error model from the scenario; the truth from ``truth.values_file`` (mm, deg)
    or, without it, a seeded draw from ``[truth.random]``."""
    nominal = Mechanism.from_xml(scenario.resolve(scenario.get("model", str)))
    params = load_parameter_set(scenario.resolve(scenario.get("error_model", str)), nominal.model)
    values_file = scenario.get("truth.values_file", str, None)
    if values_file is not None:
        truth_values = load_values(scenario.resolve(values_file), params)
    else:
        truth_values = draw_truth(params, TruthSpec.from_scenario(scenario), rng)
    truth = Mechanism(params.inject(nominal.model, truth_values), name=nominal.name)
    return ScenarioMachine(nominal, params, truth_values, truth)
