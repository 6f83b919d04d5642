"""A package's public face: names of its modules, exported from the package, loaded on use.

A face loads the module behind a name when the name is first asked for, so that importing a
package costs nothing and two packages' faces can name each other's floors in any order
without an import circle at start-up::

    __all__, __getattr__, __dir__ = face(__name__, {"batch": ("forward_batch",), ...})
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable
from typing import Any


def face(
    package: str, exports: dict[str, tuple[str, ...]]
) -> tuple[list[str], Callable[[str], Any], Callable[[], list[str]]]:
    """``__all__``, ``__getattr__`` and ``__dir__`` of ``package``: each name of ``exports``
    (module, relative to the package -> names) read from its module on first use."""
    where = {name: f"{package}.{module}" for module, names in exports.items() for name in names}

    def __getattr__(name: str) -> Any:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(where[name]), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(where) | set(vars(sys.modules[package])))

    __getattr__.where = where  # type: ignore[attr-defined]  # the house test reads it
    return sorted(where), __getattr__, __dir__
