"""The kernels' compile options, the model constants they share, and their cache's guard."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

FREE, BALL, SLIDE, HINGE = 0, 1, 2, 3  # mjtJoint
AXIS_JOINT, AXIS_WORLD, AXIS_BODY = 0, 1, 2  # as twin.kinematics.reduced

JIT = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}
JIT_INLINE = {**JIT, "inline": "always"}  # small helpers: a call passing arrays costs more

HERE = Path(__file__).resolve().parent
STAMP = "kernels.sources"


def _cache_dirs() -> list[Path]:
    """Where numba keeps these files' machine code: beside them, or below NUMBA_CACHE_DIR."""
    dirs = [HERE / "__pycache__"]
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root:
        dirs.append(Path(root) / os.path.splitdrive(str(HERE))[1].lstrip(os.sep))
    return dirs


def drop_stale_cache() -> None:
    """Remove the package's cached machine code when any kernel file changed since it was
    compiled: a kernel inlines its callees from the other files, and numba checks only the
    kernel's own file. Nothing to do when the digest of the files is the one stamped."""
    digest = hashlib.sha256()
    for f in sorted(HERE.glob("*.py")):
        digest.update(f.name.encode() + b"\0" + f.read_bytes())
    text = digest.hexdigest()
    for d in _cache_dirs():
        stamp = d / STAMP
        try:
            if stamp.read_text() == text:
                continue
        except OSError:
            pass
        if not d.is_dir():
            continue
        for f in list(d.glob("*.nbi")) + list(d.glob("*.nbc")):
            f.unlink(missing_ok=True)
        try:
            stamp.write_text(text)
        except OSError:
            pass  # a read-only cache: numba itself will not write there either
