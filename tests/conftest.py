"""Shared, read-only fixtures: the hexapod twin, its 54-parameter error model, Table 2 values.

The mechanisms are shared across the session: a test may run kinematics on them (which
writes their MjData) but must never edit their MjModel; use ``.copy()`` or
``ParameterSet.inject`` (which returns a new model) for anything that changes geometry.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.mechanism import Mechanism
from twin.parameter_file import load_parameter_set, load_values
from twin.parameters import ParameterSet

ROOT = Path(__file__).resolve().parent.parent
HEXAPOD_XML = ROOT / "models" / "hexapod_rrrprr.xml"
HEXAPOD_PARAMS = ROOT / "models" / "hexapod_rrrprr.params.toml"
HEXAPOD_TABLE2 = ROOT / "scenarios" / "truth" / "hexapod_table2.toml"


@pytest.fixture(scope="session")
def hexapod() -> Mechanism:
    return Mechanism.from_xml(HEXAPOD_XML)


@pytest.fixture(scope="session")
def hexapod_params(hexapod: Mechanism) -> ParameterSet:
    return load_parameter_set(HEXAPOD_PARAMS, hexapod.model)


@pytest.fixture(scope="session")
def table2_values(hexapod_params: ParameterSet) -> np.ndarray:
    values = load_values(HEXAPOD_TABLE2, hexapod_params)
    values.setflags(write=False)
    return values
