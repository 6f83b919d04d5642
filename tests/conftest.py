"""Shared, read-only fixtures: the hexapod twin, its 54-parameter error model, Table 2 values.

The mechanisms are shared across the session: a test may run kinematics on them (which
writes their MjData) but must never edit their MjModel; use ``.copy()`` or
``ParameterSet.inject`` (which returns a new model) for anything that changes geometry.

Under pytest-xdist (``make test``: ``--dist loadfile``) each module runs whole on one worker,
so its module fixtures are built once; a slow test that shares nothing with its module has
a module of its own, so that it can run beside it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.formats.parameter_file import load_parameter_set, load_values
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet

ROOT = Path(__file__).resolve().parent.parent
HEXAPOD_XML = ROOT / "models" / "hexapod_rrrprr.xml"
HEXAPOD_PARAMS = ROOT / "models" / "hexapod_rrrprr.params.toml"
HEXAPOD_TABLE2 = ROOT / "scenarios" / "truth" / "hexapod_table2.toml"


LONGEST = "tests/test_sweep_ray.py"  # the longest test: a local Ray beside the local engine


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The longest module first, then the others that hold an accuracy gate, then the rest;
    each module's order kept (a stable sort). ``make test``'s workers start on the slow runs,
    and none is left alone with one at the end."""
    slow = {_module(item) for item in items if item.get_closest_marker("accuracy")}
    items.sort(key=lambda item: (_module(item) != LONGEST, _module(item) not in slow))


def _module(item: pytest.Item) -> str:
    return item.nodeid.split("::")[0]


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
