"""The state at which a compensated program will run, for the error model's kinds that read it.

A result of ``identify --with`` may carry kinds whose joint offset depends on more than the
commands (twin.offset_kinds): a backlash on the direction from which each actuator approaches
the target, a thermal growth or a drift on the time since warm-up (clock ``time_s``) or the
pose count (clock ``order``), a thermal expansion on the temperature. Compensation must know
that state for every target:

* ``direction``: the program's ``dir:<actuator>`` columns, else derived from the program's
  own sequence (its ``order`` column, else the file's order): each target approached from
  the previous one, the first from the model's home configuration;
* ``time_s`` / ``temperature_c``: the program's column, else one value for every target
  (``--time-s``, ``--temperature-c``); both given is refused as ambiguous;
* ``order``: the program's ``order`` column (the clock of a fit on data without times).

A needed state that is missing is refused by name (:class:`RunStateError`); each one used is
said in a sentence.
"""

from __future__ import annotations

import numpy as np

from calib.data.program import Program
from calib.exceptions import CalibError
from calib.fit.kinds import PoseState, approach_directions
from calib.fit.model import CalibrationModel

WHAT = {
    "time_s": ("the time since warm-up (s)", "--time-s S"),
    "temperature_c": ("the temperature (deg C)", "--temperature-c T"),
    "order": ("the pose count since the fit's origin (clock 'order')", None),
}


class RunStateError(CalibError):
    """A state the result's kinds read that the program and the options do not give."""


def _users(model: CalibrationModel, need: str) -> str:
    from twin.offset_kinds import needed_column

    assert model.offsets is not None
    names = [
        p.name for p in model.offsets.parameters if needed_column(p.kind, p.constants_dict) == need
    ]
    kinds = sorted({p.kind for p in model.offsets.parameters if p.name in names})
    return f"{'/'.join(kinds)} ({', '.join(names[:3])}{' ...' if len(names) > 3 else ''})"


def run_state(
    model: CalibrationModel,
    program: Program | None,
    n: int,
    time_s: float | None = None,
    temperature_c: float | None = None,
) -> tuple[PoseState | None, list[str]]:
    """The state of the ``n`` targets (those of ``program``, or desired poses without one)
    that the model's offset kinds need, and a sentence per state used; None without such
    kinds. Raises :class:`RunStateError` naming what is missing."""
    needs = () if model.offsets is None else model.offsets.needs
    if not needs:
        return None, []
    cols = {} if program is None else program.state
    got: dict[str, np.ndarray] = {}
    said: list[str] = []
    for need in needs:
        if need == "direction":
            if "direction" in cols:
                got[need] = cols["direction"]
                said.append("approach directions: the program's dir:<actuator> columns")
                continue
            if program is None:
                raise RunStateError(
                    f"the result's {_users(model, need)} reads each target's approach "
                    "direction: give --commands program.csv (its dir:<actuator> columns, or its "
                    "order) with the targets"
                )
            order = cols.get("order", np.arange(len(program), dtype=float))
            mech = model.nominal
            home = mech.home_qpos[mech.actuator_qpos]
            got[need] = approach_directions(program.commands, order, home)
            source = "its order column" if "order" in cols else "the file's order"
            said.append(
                f"approach directions: derived from the program's sequence ({source}; each "
                "target approached from the previous one, the first from the model's home "
                "configuration)"
            )
            continue
        what, option = WHAT[need]
        single = {"time_s": time_s, "temperature_c": temperature_c}.get(need)
        if need in cols and single is not None:
            raise RunStateError(
                f"{need}: both the program's column and {option.split()[0]} given; give one"
            )
        if need in cols:
            got[need] = cols[need]
            lo, hi = float(np.min(cols[need])), float(np.max(cols[need]))
            said.append(f"{need}: the program's column ({lo:g} to {hi:g})")
        elif single is not None:
            got[need] = np.full(n, float(single))
            said.append(f"{need}: {single:g} for every target ({option.split()[0]})")
        else:
            how = f"{option} or a {need} column" if option else f"an {need} column"
            where = " in the program" if program is not None else " (--commands program.csv)"
            raise RunStateError(
                f"the result's {_users(model, need)} reads {what}: give {how}{where}"
            )
    state = PoseState(
        n,
        got.get("direction"),
        got.get("time_s"),
        got.get("order"),
        got.get("temperature_c"),
        said[0] if "direction" in got else "",
    )
    return state, said
