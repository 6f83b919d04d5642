"""Locks that say a file or folder is in use by a live process, on any OS.

A writer holds ``<path>.lock`` (the ``filelock`` package: ``fcntl`` on POSIX, ``msvcrt`` on
Windows) while its hidden working files exist; the OS drops the lock when the process dies,
so a later process that can take it knows the working files are a killed one's leftovers.
``filelock`` is imported on first use: importing the command line needs no lock module.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any

LOCK_SUFFIX = ".lock"


def lock_path(path: str | os.PathLike[str]) -> Path:
    """The lock file of ``path``: ``<path>.lock`` beside it."""
    p = Path(path)
    return p.with_name(p.name + LOCK_SUFFIX)


def take(lock: str | os.PathLike[str], timeout: float = 0.0) -> Any | None:
    """Hold the lock file ``lock`` (waiting up to ``timeout`` s); the held lock, or None when
    a live process holds it."""
    from filelock import FileLock, Timeout

    held = FileLock(str(lock))
    try:
        held.acquire(timeout=timeout)
    except Timeout:
        return None
    return held


def drop(held: Any | None, remove: bool = True) -> None:
    """Release a lock from :func:`take` and (``remove``) delete its file: only for lock files
    of unique names, which no other process waits on."""
    if held is None:
        return
    held.release()
    if remove:
        with contextlib.suppress(OSError):
            os.unlink(held.lock_file)


def is_free(lock: str | os.PathLike[str]) -> bool:
    """Whether no live process holds ``lock`` (then the lock is not kept)."""
    held = take(lock)
    drop(held, remove=False)
    return held is not None
