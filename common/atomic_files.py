"""Files written whole or not at all, with the permissions of an ordinary file (0644).

Every result the project writes (JSON, Markdown, CSV, PNG, recordings) goes through a
temporary sibling and ``os.replace``, so a reader never sees half a file and an interrupted
write leaves the previous file in place. ``tempfile.mkstemp`` creates files 0600; the final
file gets 0644 less the process umask, like a file made by ``open``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

FILE_MODE = 0o644


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def ordinary_mode() -> int:
    """0644 less the umask: the mode ``open(path, "w")`` would give a new file."""
    return FILE_MODE & ~_umask()


def plain_json(value: Any) -> Any:
    """JSON-ready copy: numpy scalars and arrays to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): plain_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain_json(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, Path):
        return str(value)
    return value


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str = ".tmp") -> Iterator[Path]:
    """Yield a temporary sibling of ``path`` to write; on success it replaces ``path``.

    On any exception (KeyboardInterrupt included) the temporary file is removed and ``path``
    is left as it was."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, ordinary_mode())
        os.replace(tmp, target)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    return Path(path)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    return Path(path)


def json_text(data: Any) -> str:
    """``data`` as strict JSON text (NaN and inf become null), indented, newline-ended."""
    return json.dumps(plain_json(data), indent=2, allow_nan=False) + "\n"


def write_json_atomic(path: str | os.PathLike[str], data: Any) -> Path:
    """Write ``data`` as strict JSON (NaN and inf become null) atomically."""
    return write_text_atomic(path, json_text(data))


def write_figure_png(fig: Any, path: str | os.PathLike[str], dpi: int = 110) -> Path:
    """A matplotlib figure as a PNG at ``path``, written whole or not at all; the figure is
    closed either way."""
    import matplotlib.pyplot as plt  # on first use: nothing else here plots

    try:
        return write_with_atomic(path, lambda tmp: fig.savefig(tmp, format="png", dpi=dpi))
    finally:
        plt.close(fig)


def write_with_atomic(
    path: str | os.PathLike[str], writer: Callable[[Path], None], suffix: str = ".tmp"
) -> Path:
    """Let ``writer(tmp_path)`` produce the file (e.g. ``savefig``), then swap it in."""
    with atomic_path(path, suffix=suffix) as tmp:
        writer(tmp)
    return Path(path)
