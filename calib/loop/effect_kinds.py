"""What a diagnosis names, as parameters of the error model: the loop closed in files.

``pkm-calib diagnose --out D.json`` writes, beside the named effect's fit, the error-model
parameters that carry it (static kinds: a function of the commanded pose alone; and the
offsets of calib.loop.offset_effects, which also read the state at each reading):

* ``gain_error``        one ``actuator_gain`` per actuator (the joint travels (1 + g) times
                        its commanded travel from its zero)
* ``reflector_offsets`` ``site_pos`` offsets of the reflectors the error model lacks
* ``joint_axis_errors`` ``body_rot`` tilts of the joint axes the error model lacks
* ``gravity_compliance`` one ``joint_compliance`` per actuator whose load the fit saw (a joint
                        no gravity load reaches, such as a vertical first axis or a last axis
                        the payload sits on, has no column in the diagnosis and none here):
                        on a model without declared masses the compliance times the payload's
                        mass under a tool payload (``<a>.compliance_x_payload``, no
                        ``payload_kg``), the diagnosis's own product; on a model with masses
                        the compliance (``<a>.compliance``) under its own masses plus the
                        payload the diagnosis's scan chose, written as the parameters'
                        ``payload_kg`` so that the kind's load is the one the diagnosis fitted

``pkm-calib identify --with D.json`` adds them to the error model and refits geometry and effect
together; the result file lists them (``added_parameters``), and :func:`model_for_result`
rebuilds that model wherever the result is read. An effect of the tracker, or one that grows
the whole structure (thermal_expansion of the diagnosis), is no kind of the error model: it is
said so, and its before and after stay the diagnosis's own.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from calib.diagnosis.context import extra_parameters
from calib.exceptions import CalibError
from calib.fit.model import CalibrationModel
from calib.loop.offset_effects import OFFSET_EFFECTS, offset_parameters
from twin.offset_kinds import CONSTANTS
from twin.parameters import Parameter, ParameterSet

# the effects the error model carries: the static kinds, then the offsets of the joint values
# by the commands and the state at the reading (calib.loop.offset_effects)
STATIC = (
    "gain_error",
    "reflector_offsets",
    "joint_axis_errors",
    "gravity_compliance",
    *OFFSET_EFFECTS,
)
# why the others are no kind of the error model
NOT_STATIC = {
    "thermal_expansion": "it grows the whole structure about the base in time, no actuator's "
    "offset (the error model's thermal_expansion kind is an actuator's, in temperature)",
    "tracker_drift": "it is the tracker's, in time, not the machine's",
    "tracker_scale": "it is the tracker's scale, not the machine's",
}


def not_static_reason(name: str) -> str:
    """Why ``name`` stays the diagnosis's own, in a clause."""
    return NOT_STATIC.get(name, "it is no static kind of the error model")


class EffectFileError(CalibError):
    """A diagnosis file that cannot be used to extend the error model."""


def parameters_for(
    model: CalibrationModel,
    effect: str,
    fitted: dict[str, Any] | None = None,
    clock: str = "order",
    origin: float = 0.0,
) -> list[Parameter]:
    """The error-model parameters that carry the static ``effect`` on this model (those it
    already holds left out); ``fitted``: the diagnosis's fit of the effect (its
    ``effect_parameters`` entry: parameter -> value, std, unit; the shape likewise), which
    the compliance reads."""
    if effect == "gravity_compliance":
        return compliance_parameters(model, fitted)
    if effect in OFFSET_EFFECTS:  # on the diagnosis's clock and time origin
        mech = model.nominal
        slide = tuple(bool(s) for s in mech.actuator_is_slide)
        have = set(model.params.names)
        return offset_parameters(effect, mech.actuator_names, slide, fitted, clock, origin, have)
    if effect == "gain_error":
        have = {(p.kind, p.element) for p in model.params.parameters if p.kind == "actuator_gain"}
        return [
            Parameter(f"{a}.gain", "actuator_gain", a)
            for a in model.nominal.actuator_names
            if ("actuator_gain", a) not in have
        ]
    if effect in ("reflector_offsets", "joint_axis_errors"):
        return list(extra_parameters(model)[effect])
    raise EffectFileError(f"'{effect}' is no static kind of the error model (those: {STATIC})")


def compliance_parameters(
    model: CalibrationModel, fitted: dict[str, Any] | None = None
) -> list[Parameter]:
    """One ``joint_compliance`` per actuator for the diagnosis's ``gravity_compliance``,
    named as the diagnosis names its parameters, under the load the diagnosis fitted: the
    tool payload alone per kg on a model without declared masses, the model's masses plus
    the payload its scan chose (``fitted``'s ``payload``, kg; none fitted: 0) otherwise. An
    actuator whose parameter the fit did not see (value 0 without a standard error) is left
    out, as is one the error model already gives a compliance."""
    nominal = model.nominal
    per_kg = nominal.masses_defaulted
    suffix = "compliance_x_payload" if per_kg else "compliance"
    fitted = fitted or {}
    payload = None
    if not per_kg:
        shape = fitted.get("payload") or {}
        payload = float(shape["value"]) if isinstance(shape.get("value"), (int, float)) else 0.0
    have = {p.element for p in model.params.parameters if p.kind == "joint_compliance"}
    out = []
    for a in nominal.actuator_names:
        entry = fitted.get(f"{a}.{suffix}")
        unseen = entry is not None and entry.get("std") is None and entry.get("value") == 0.0
        if a in have or unseen:
            continue
        out.append(Parameter(f"{a}.{suffix}", "joint_compliance", a, payload_kg=payload))
    return out


def static_parts(chosen: str) -> tuple[list[str], list[str]]:
    """The named effects ('a+b') split into static kinds and the others."""
    names = [] if chosen in ("none", "") or chosen.startswith("unexplained") else chosen.split("+")
    return [n for n in names if n in STATIC], [n for n in names if n not in STATIC]


def effect_content(
    model: CalibrationModel,
    chosen: str,
    fitted: dict[str, dict] | None = None,
    time_unit: str = "pose",
    time_origin: float = 0.0,
) -> dict[str, Any]:
    """The ``effect`` block of a diagnosis file: which parameters identify --with adds
    (``fitted``: the diagnosis's ``effect_parameters``, by effect; ``time_unit`` "s" or
    "pose" and ``time_origin``: its time axis, the clock of the time kinds)."""
    static, other = static_parts(chosen)
    fits = fitted or {}
    clock = "time_s" if time_unit == "s" else "order"
    adds = [
        parameter_entry(p)
        for name in static
        for p in parameters_for(model, name, fits.get(name), clock, time_origin)
    ]
    return {
        "named": chosen,
        "model": model.nominal.name,
        "static": static,
        "not_static": other,
        "not_static_reasons": {n: not_static_reason(n) for n in other},
        "added_parameters": adds,
    }


def parameter_entry(p: Parameter) -> dict[str, Any]:
    """``p`` as an entry of ``added_parameters`` (a compliance's ``payload_kg`` with it)."""
    out: dict[str, Any] = {
        "name": p.name,
        "kind": p.kind,
        "element": p.element,
        "axis": [float(a) for a in p.axis],
    }
    if p.payload_kg is not None:
        out["payload_kg"] = float(p.payload_kg)
    out.update(p.constants_dict)  # an offset kind's period, phase, clock, ...
    return out


def _parameter(entry: Any, where: str) -> Parameter:
    if not isinstance(entry, dict) or not {"name", "kind", "element"} <= set(entry):
        raise EffectFileError(f"{where}: each added parameter needs name, kind and element")
    axis = entry.get("axis", [0.0, 0.0, 0.0])
    try:
        return Parameter(
            str(entry["name"]),
            str(entry["kind"]),
            str(entry["element"]),
            tuple(map(float, axis)),
            entry.get("payload_kg"),
            {c: entry[c] for c in CONSTANTS if c in entry},
        )
    except (TypeError, ValueError) as exc:
        raise EffectFileError(f"{where}: {exc}") from None


def extended_model(
    model: CalibrationModel, added: Iterable[dict[str, Any]], where: str = "added parameters"
) -> CalibrationModel:
    """``model`` with the parameters ``added`` (dicts: name, kind, element, axis) appended."""
    extra = [_parameter(e, where) for e in added]
    if not extra:
        return model
    names = set(model.params.names)
    clash = [p.name for p in extra if p.name in names]
    if clash:
        raise EffectFileError(f"{where}: {clash[:3]} are already in the error model")
    params = ParameterSet([*model.params.parameters, *extra], model.nominal.model)
    return CalibrationModel(model.nominal, params)


def model_for_result(model: CalibrationModel, data: dict[str, Any]) -> CalibrationModel:
    """The model a result was identified with: the error model plus what ``identify --with``
    added (the result's ``added_parameters``)."""
    return extended_model(model, data.get("added_parameters") or [], "the result's parameters")


def load_effect(path: str, model: CalibrationModel, allow_empty: bool = False) -> dict[str, Any]:
    """The ``effect`` block of a diagnosis file written by ``diagnose --out``, checked
    against ``model``: its static parameters to add (refused when there are none, unless
    ``allow_empty``: the file carries a residual correction to hold)."""
    import json
    from pathlib import Path

    p = Path(path)
    if not p.is_file():
        raise EffectFileError(f"diagnosis file not found: {p}")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise EffectFileError(f"{p} is not a diagnosis file (JSON, UTF-8): {exc}") from None
    return effect_block(data, model, str(p), allow_empty)


def effect_block(
    data: Any, model: CalibrationModel, where: str, allow_empty: bool = False
) -> dict[str, Any]:
    """:func:`load_effect` of a diagnosis file's content ``data`` (``where``: its name)."""
    block = data.get("effect") if isinstance(data, dict) else None
    if not isinstance(block, dict):
        raise EffectFileError(
            f"{where} has no 'effect' block: write it with `pkm-calib diagnose --out`"
        )
    if block.get("model") != model.nominal.name:
        raise EffectFileError(
            f"{where} diagnosed model '{block.get('model')}', not '{model.nominal.name}'"
        )
    named = str(block.get("named", "none"))
    if allow_empty and not block.get("added_parameters"):
        return {**block, "added_parameters": []}
    if not block.get("added_parameters"):
        other = block.get("not_static") or []
        why = (
            f"it named {', '.join(other)}, which is no static kind of the error model ("
            + "; ".join(f"{n}: {not_static_reason(n)}" for n in other)
            + "); its before and after are the diagnosis's own"
            if other
            else f"it named no effect ({named}): there is nothing to add"
        )
        raise EffectFileError(f"{where}: {why}")
    return block
