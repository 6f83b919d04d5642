"""The identified machine a result file describes: the one place a result becomes a model.

``compensate`` (corrected commands), ``export`` (the calibrated MJCF) and a user's own script
all start here: the nominal model and error model the user names, the result file checked
against them (same machine, same parameters), the identified values injected, and the
tracker registration when the readings were in the tracker's frame. The parameters
``identify --with`` added (an effect a diagnosis named: actuator gains, reflector offsets,
joint-axis tilts, joint compliances; calib.loop.effect_kinds) join the error model here, so that
every consumer sees the same machine: the geometry as a mechanism, the gains and compliances
as the map from commands to joint values (calib.fit.model.CalibrationModel).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.data.result_file import CalibrationResult, load_result
from calib.fit.model import CalibrationModel
from calib.fit.registration import Registration
from calib.loop.effect_kinds import model_for_result
from twin.mechanism import Mechanism


@dataclass(frozen=True)
class IdentifiedMachine:
    """The nominal model with a result's values: what the calibration says the machine is."""

    model: CalibrationModel  # nominal mechanism + error model (+ what the result added)
    values: np.ndarray  # SI, one per parameter of ``model.params``
    result: CalibrationResult
    registration: Registration | None  # base_from_tracker, for tracker-frame results

    @property
    def mechanism(self) -> Mechanism:
        """The nominal mechanism with the identified geometry injected (its actuated joints'
        values are joint values: :meth:`commands_for_joints` maps them to commands)."""
        return self.model.mechanism(self.values)

    def commands_for_joints(self, joints: np.ndarray, qpos: np.ndarray | None = None) -> np.ndarray:
        """The commands (N, A) that give the actuated joints' values (N, A) (through the
        identified joint compliances, under the loads at their configurations ``qpos``
        (N, nq) if known, and actuator gains; the joint values themselves without them)."""
        return self.model.commands_for_joints(self.values, joints, qpos)

    def joints_for_commands(self, commands: np.ndarray) -> np.ndarray:
        """The actuated joints' values (N, A) the commands (N, A) give."""
        return self.model.joints_for_commands(self.values, commands)

    @property
    def nominal(self) -> Mechanism:
        return self.model.nominal

    @property
    def frame(self) -> str:
        """The frame of the readings the result was identified from: 'base' or 'tracker'."""
        return str(self.result.data.get("frame", "base"))


def identified_machine(model: CalibrationModel, result: CalibrationResult) -> IdentifiedMachine:
    """The machine ``result`` describes on ``model`` (extended by the parameters the result
    added); a result of another machine or another error model is refused
    (calib.data.result_file.ResultFileError, naming the mismatch)."""
    if result.model != model.nominal.name:
        from calib.data.result_file import ResultFileError

        raise ResultFileError(
            f"{result.path} is a result for model '{result.model}', not for "
            f"'{model.nominal.name}' (another machine)"
        )
    model = model_for_result(model, result.data)
    values = result.values_for(model.params)
    _check_plausible(result, model)
    values.setflags(write=False)
    return IdentifiedMachine(model, values, result, result.registration)


# a value this many times the plausible size of its kind (calib.fit.verdict: 50 mm, 20 deg,
# 20 % of a gain) is no calibration error identify estimates, nor one it would accept: a
# file edited or damaged after identify wrote it
IMPLAUSIBLE_FACTOR = 10.0


def _check_plausible(result: CalibrationResult, model: CalibrationModel) -> None:
    """Refuse (ResultFileError, naming them) a result whose values lie far beyond what an
    error of their kind can be on a built machine."""
    from calib.data.result_file import ResultFileError
    from calib.fit.verdict import implausible_estimates

    units = model.params.display_units()
    shown = np.asarray(result.display_values, dtype=float) / IMPLAUSIBLE_FACTOR
    named = implausible_estimates(result.names, shown, units)
    if named:
        bad = [n.split(" = ")[0] for n in named]
        values = {n: v for n, v in zip(result.names, result.display_values, strict=True)}
        listed = ", ".join(
            f"{n} = {values[n]:+.6g} {u}"
            for n, u in zip(result.names, units, strict=True)
            if n in bad
        )
        raise ResultFileError(
            f"{result.path}: implausible estimate(s): {listed} (more than "
            f"{IMPLAUSIBLE_FACTOR:g} times the plausible size of an error of its kind: 50 mm, "
            "20 deg); not a result identify writes: was the file edited? Identify again"
        )


def load_identified_machine(model: CalibrationModel, path: str | Path) -> IdentifiedMachine:
    """:func:`identified_machine` of the result file ``path``."""
    return identified_machine(model, load_result(path, expected_model=model.nominal.name))
