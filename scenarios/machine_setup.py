"""What every study starts from: the nominal machine, its error model and the truth twin."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.fit import CalibrationModel
from scenarios.config import Scenario, ScenarioError, values_file_problems
from scenarios.config.effects import EFFECTS
from scenarios.truth_draw import TruthSpec, draw_truth
from twin.exceptions import ModelError, ParameterError
from twin.formats import load_parameter_set, load_values
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet


@dataclass(frozen=True)
class ScenarioMachine:
    nominal: Mechanism
    params: ParameterSet
    truth_values: np.ndarray  # SI
    truth: Mechanism  # the nominal model with the truth injected: the twin side only

    def calibration_model(self) -> CalibrationModel:
        return CalibrationModel(self.nominal, self.params)


def load_nominal(scenario: Scenario) -> tuple[Mechanism, ParameterSet]:
    """The nominal mechanism (``model``) and its error model (``error_model``); a file that
    does not load is a ScenarioError naming the scenario key and the file's complaint."""
    model_path = scenario.resolve(scenario.get("model", str), "model")
    try:
        nominal = Mechanism.from_xml(model_path)
    except (ModelError, ValueError) as exc:
        raise ScenarioError(f"{scenario.path}: 'model' ({model_path}): {exc}") from exc
    params_path = scenario.resolve(scenario.get("error_model", str), "error_model")
    try:
        params = load_parameter_set(params_path, nominal.model)
    except (ParameterError, ModelError) as exc:
        raise ScenarioError(f"{scenario.path}: 'error_model' ({params_path}): {exc}") from exc
    return nominal, params


def load_truth_values(scenario: Scenario, params: ParameterSet, rng: np.random.Generator):
    """The truth (SI): ``truth.values_file`` (mm, deg) or a seeded draw from [truth.random]."""
    values_file = scenario.get("truth.values_file", str, None)
    if values_file is None:
        return draw_truth(params, TruthSpec.from_scenario(scenario), rng)
    path = scenario.resolve(values_file, "truth.values_file")
    problems = values_file_problems(
        path, scenario.resolve(scenario.get("error_model", str), "error_model")
    )
    if problems:
        raise ScenarioError(f"{scenario.path}: 'truth.values_file': {problems[0]}")
    try:
        return load_values(path, params)
    except ParameterError as exc:
        raise ScenarioError(f"{scenario.path}: 'truth.values_file': {exc}") from exc


def load_machine(scenario: Scenario, rng: np.random.Generator) -> ScenarioMachine:
    """Model and error model from the scenario; the truth from ``truth.values_file`` (mm, deg)
    or, without it, a seeded draw from ``[truth.random]``."""
    nominal, params = load_nominal(scenario)
    truth_values = load_truth_values(scenario, params, rng)
    truth = nominal.with_model(params.inject(nominal.model, truth_values))
    return ScenarioMachine(nominal, params, truth_values, truth)


def build_effects(scenario: Scenario) -> list:
    """The effects of ``truth.effects``, each ``{ kind = "...", <constructor arguments> }``."""
    out = []
    for i, entry in enumerate(scenario.get("truth.effects", list, [])):
        kind = entry.get("kind")
        where = f"{scenario.path}: 'truth.effects[{i}]'"
        if kind not in EFFECTS:
            raise ScenarioError(f"{where}: unknown effect '{kind}'; known: {list(EFFECTS)}")
        # a TOML array is a list; the effects take tuples (e.g. gravity, phases_rad)
        args = {k: tuple(v) if isinstance(v, list) else v for k, v in entry.items() if k != "kind"}
        try:
            out.append(EFFECTS[kind](**args))
        except (TypeError, ValueError) as exc:
            raise ScenarioError(f"{where}: effect '{kind}': {exc}") from exc
    return out
