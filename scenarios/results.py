"""Writing results atomically: a reader never sees a half-written summary or report.

The writers live in :mod:`common.atomic_files` (the calibration's command line uses them
too); this module keeps the names the scenarios import.
"""

from __future__ import annotations

from common.atomic_files import plain_json as _plain
from common.atomic_files import write_json_atomic, write_text_atomic

__all__ = ["_plain", "write_json_atomic", "write_text_atomic"]
